"""The one progress bar of every long job (dissect, export, batch, long demos, conformance): rich,
on stderr, drawn only when stderr is a terminal and never where it could land between records
(records on stdout: only if stdout is a file). Library functions take a plain
``progress(done, total)`` callback; rich is imported only when a bar is drawn.
"""

from __future__ import annotations

import contextlib
import os
import stat
import sys
import time
from types import TracebackType
from typing import Any

LABEL = 28  # characters of the label: the bar fits an 80-column terminal
REFRESH = 0.1  # s between two updates of the bar (rich redraws at most this often anyway)


def stdout_is_file() -> bool:
    """stdout is a regular file or a character device that is not a terminal (/dev/null)."""
    try:
        mode = os.fstat(sys.stdout.fileno()).st_mode
        return stat.S_ISREG(mode) or (stat.S_ISCHR(mode) and not sys.stdout.isatty())
    except (OSError, ValueError, AttributeError):
        return False


def bar_allowed(records_on_stdout: bool) -> bool:
    """Whether a bar may be drawn: stderr a terminal, and stdout not a pipe or terminal that
    carries the records."""
    try:
        if not sys.stderr.isatty():
            return False
    except (ValueError, AttributeError):
        return False
    return not records_on_stdout or stdout_is_file()


class JobProgress:
    """``with JobProgress("reading x.pcapng", total) as p: ... p.update(done)``: a no-op when
    :func:`bar_allowed` says no, gone when the job ends whatever way it ends."""

    def __init__(self, label: str, total: float | None = None, *, unit: str = "bytes",
                 records_on_stdout: bool = False, enabled: bool | None = None) -> None:
        self.label = label if len(label) <= LABEL else label[:LABEL - 1] + "\u2026"
        self.total = total
        self.unit = unit
        self.enabled = bar_allowed(records_on_stdout) if enabled is None else enabled
        self._progress: Any = None
        self._task: Any = None
        self._last = 0.0

    def __enter__(self) -> JobProgress:
        if not self.enabled:
            return self
        try:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                DownloadColumn,
                MofNCompleteColumn,
                Progress,
                TaskProgressColumn,
                TextColumn,
                TimeRemainingColumn,
                TransferSpeedColumn,
            )
        except ImportError:
            self.enabled = False
            return self
        amount = ([DownloadColumn(), TransferSpeedColumn()] if self.unit == "bytes"
                  else [MofNCompleteColumn(), TextColumn(self.unit)])
        self._progress = Progress(
            TextColumn("{task.description}"), BarColumn(bar_width=16), TaskProgressColumn(),
            *amount, TextColumn("ETA"), TimeRemainingColumn(),
            console=Console(file=sys.stderr, stderr=True), transient=True,
            redirect_stdout=False, redirect_stderr=False, speed_estimate_period=10.0)
        self._progress.start()
        self._task = self._progress.add_task(self.label, total=self.total)
        return self

    def update(self, done: float, total: float | None = None) -> None:
        """``done`` of ``total`` (the total given at the start when None). Cheap: the bar is
        touched at most every :data:`REFRESH` s, and always at the end."""
        if self._progress is None:
            return
        now = time.monotonic()
        if total is not None:
            self.total = total
        if now - self._last < REFRESH and (self.total is None or done < self.total):
            return
        self._last = now
        self._progress.update(self._task, completed=done, total=self.total)

    def print(self, line: str) -> None:
        """A line on stderr above the bar (or plainly when there is no bar)."""
        if self._progress is not None:
            self._progress.console.print(line, markup=False, highlight=False, soft_wrap=True)
        else:
            print(line, file=sys.stderr)

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._progress is not None:
            with contextlib.suppress(OSError, ValueError):  # stderr gone: nothing to clear
                self._progress.stop()
            self._progress = None

