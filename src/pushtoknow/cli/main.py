"""The `pushtoknow` command line (typer + rich): it parses options and prints results; the
library does the work. Commands live in one module per group (data, models, evaluation,
identify, real data, bench); this module registers them and turns user errors into one line."""

from __future__ import annotations

import errno
import sys

import typer

from pushtoknow.cli import (  # noqa: F401 (commands)
    bench,
    data,
    evaluate_real,
    evaluation,
    identify,
    models,
)
from pushtoknow.cli.estimate_real import register as _register_real
from pushtoknow.cli.shared import app, err_console, print_error, validation_summary
from pushtoknow.common.errors import DiskFullError, PushToKnowError, first_line

_register_real(app)


def error_message(e: BaseException) -> str | None:
    """The one-line message of an error a user can cause (bad options, input, files, disk), or
    None for a bug (which keeps its traceback)."""
    if hasattr(e, "format_message") and getattr(e, "exit_code", None) == 2:  # a usage error
        return f"{first_line(e.format_message())} (see --help)"
    if isinstance(e, PushToKnowError):
        return first_line(e)
    if (summary := validation_summary(e)) is not None:
        return summary
    if isinstance(e, OSError) and e.strerror:
        if e.errno == errno.ENOSPC and e.filename:
            return str(DiskFullError(e.filename))
        where = f"{e.filename}: " if e.filename else ""
        return f"{where}{e.strerror.lower()}"
    return None


def main() -> None:  # pragma: no cover - the installed entry point; tests call it in process
    try:
        code = app(standalone_mode=False)  # errors come here, to be told in one line
    except typer.Abort:
        err_console.print("aborted")
        sys.exit(130)
    except Exception as e:
        if type(e).__name__ == "NoArgsIsHelpError":  # no command: the help was printed
            sys.exit(2)
        message = error_message(e)
        if message is None:
            raise
        print_error(message)
        sys.exit(2)
    sys.exit(code if isinstance(code, int) else 0)
