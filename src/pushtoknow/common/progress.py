"""The progress bar of long library jobs: on stderr (results go to stdout), counting done of all."""

from __future__ import annotations

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


def progress_bar(enabled: bool = True, remaining: bool = True) -> Progress:
    """A rich Progress on stderr: description, bar, done/total and the time remaining (or
    elapsed, with `remaining=False`); `enabled=False` shows nothing."""
    return Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn() if remaining else TimeElapsedColumn(),
        disable=not enabled,
        console=Console(stderr=True, emoji=False),
    )
