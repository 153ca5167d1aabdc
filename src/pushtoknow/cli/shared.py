"""What the command modules share: the app and its groups, the consoles, option parsing and
output helpers (one-line errors, JSON or tables, the reproducing command line)."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import enum

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from pushtoknow.common.errors import first_line
from pushtoknow.testbed.push import PROFILES

ProfileName = enum.Enum("ProfileName", {p: p for p in PROFILES}, type=str)  # CLI choices

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Learn an object's mass, friction, CoM and inertia by pushing it.",
)
dataset_app = typer.Typer(no_args_is_help=True, help="Inspect datasets.")
bench_app = typer.Typer(no_args_is_help=True, help="Benchmarks (speed and memory).")
app.add_typer(dataset_app, name="dataset")
app.add_typer(bench_app, name="bench")
console = Console(emoji=False)  # object names such as random:7:0:kite are not emoji codes
err_console = Console(stderr=True, soft_wrap=True, emoji=False)


def _version(value: bool) -> None:
    if value:
        from pushtoknow.common.version import __version__

        print(f"pushtoknow {__version__}")
        raise typer.Exit()


@app.callback()
def _main_options(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="print the version and exit"
    ),
) -> None:
    """Learn an object's mass, friction, CoM and inertia by pushing it."""
    show_warnings_as_lines()


def show_warnings_as_lines() -> None:
    """Print each `PushToKnowWarning` as one 'warning: …' line on stderr (every time it is
    raised); other warnings are shown as Python shows them."""
    import warnings

    from pushtoknow.common.errors import PushToKnowWarning

    shown = warnings.showwarning
    if getattr(shown, "pushtoknow", False):
        return

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, PushToKnowWarning):
            print_warning(str(message))
        else:
            shown(message, category, filename, lineno, file, line)

    show.pushtoknow = True
    warnings.showwarning = show
    warnings.simplefilter("always", PushToKnowWarning)


PROFILES_HELP = (
    "comma-separated speed profiles the policy may use: constant,release "
    "(default: those the model was trained on)"
)


def save_and_print_json(data: dict, out: Path | None, as_json: bool) -> bool:
    """Write `data` to `out` (if given) and print it as JSON (if `as_json`); True when printed,
    so the caller skips its tables."""
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(data, indent=1))
    if as_json:
        print(json.dumps(data))
    return as_json


REPORT_OPTIONS = {"markdown", "as_json", "append"}  # how a result is shown, not what it is


def command_line(ctx: typer.Context) -> str:
    """The command that reproduces this one's results: its path and every option given a value
    other than its default (output-display options left out), for reports."""
    import enum as _enum
    import shlex

    names, level = [], ctx  # the subcommands' names: the program's own (`python -m …`) left out
    while level.parent is not None:
        names.append(level.info_name)
        level = level.parent
    parts = ["pushtoknow", *reversed(names)]
    for p in ctx.command.params:
        value = ctx.params.get(p.name)
        if p.name in REPORT_OPTIONS or value is None or value == p.default or value == []:
            continue
        values = value if isinstance(value, (list, tuple)) else [value]
        for v in values:
            v = v.value if isinstance(v, _enum.Enum) else v
            flag = p.opts[0] if p.opts[0].startswith("-") else None
            if isinstance(v, bool):
                parts.append(flag if v else p.secondary_opts[0] if p.secondary_opts else "")
            else:
                parts += [flag, str(v)] if flag else [str(v)]
    return shlex.join([x for x in parts if x])


IMAGE_FORMATS = ("png", "jpg", "jpeg", "pdf", "svg")


def image_out(path: Path, option: str = "--out") -> Path:
    """An image path checked before any work: a known format (no suffix: .png), not a folder."""
    if path.is_dir():
        raise typer.BadParameter(f"{option} {path}: is a folder, not an image file")
    suffix = path.suffix.lower().lstrip(".")
    if not suffix:
        return path.with_suffix(".png")
    if suffix not in IMAGE_FORMATS:
        raise typer.BadParameter(
            f"{option} {path}: unsupported image format '{suffix}' ({', '.join(IMAGE_FORMATS)})"
        )
    return path


def out_folder(path: Path | None, option: str = "--out") -> None:
    """Refuse, before any work, an output folder that is an existing file or that cannot be
    written: the nearest existing folder at or above it is a file or refuses a new file (a
    read-only file system, no permission)."""
    if path is None:
        return
    if path.exists() and not path.is_dir():
        raise typer.BadParameter(f"{option} {path}: is a file, not a folder")
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise typer.BadParameter(f"{option} {path}: {existing} is a file, not a folder")
    try:
        tempfile.TemporaryFile(dir=existing).close()
    except OSError as e:
        why = (e.strerror or str(e)).lower()
        raise typer.BadParameter(f"{option} {path}: cannot write in {existing} ({why})") from None


def flatten(data: dict, prefix: str = "") -> list[tuple[str, str]]:
    rows = []
    for k, v in data.items():
        if isinstance(v, dict):
            rows += flatten(v, f"{prefix}{k}.")
        else:
            rows.append((f"{prefix}{k}", f"{v:.4g}" if isinstance(v, float) else str(v)))
    return rows


def print_result(data: dict, as_json: bool, title: str) -> None:
    """A command's result on stdout: JSON with --json, else a table of its (flattened) fields."""
    if as_json:
        print(json.dumps(data))
        return
    t = Table(title=title)
    t.add_column("field")
    t.add_column("value", justify="right")
    for k, v in flatten(data):
        t.add_row(k, v)
    console.print(t)


def parse_profiles(text: str) -> tuple[str, ...]:
    """'constant,release' → ("constant", "release"), each checked."""
    names = tuple(p.strip() for p in text.split(",") if p.strip())
    bad = [p for p in names if p not in PROFILES]
    if not names or bad:
        raise typer.BadParameter(
            f"--profiles: unknown profile(s) {bad or text!r}; choose from {', '.join(PROFILES)}"
        )
    return names


def validation_summary(e: Exception) -> str | None:
    """'field: problem; …' for a settings validation error (pydantic), else None."""
    from pydantic import ValidationError

    if not isinstance(e, ValidationError):
        return None
    return "; ".join(f"{'.'.join(map(str, d['loc'])) or '<root>'}: {d['msg']}" for d in e.errors())


def print_error(message: str) -> None:
    """'error: MESSAGE' on stderr, the message as it is (brackets in it are text, not markup)."""
    err_console.print(f"[bold red]error:[/] {escape(message)}", highlight=False)


def print_warning(message: str) -> None:
    """'warning: MESSAGE' on stderr, one line (brackets in it are text)."""
    err_console.print(f"[bold yellow]warning:[/] {escape(message)}", highlight=False)


def fail(e: Exception) -> None:
    """Print `e` as a one-line error and exit with status 2."""
    print_error(validation_summary(e) or first_line(e))
    raise typer.Exit(2)
