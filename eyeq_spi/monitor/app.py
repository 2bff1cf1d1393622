"""The monitor's loop: advance the source until the next redraw, draw, repeat. On a terminal the
screen is redrawn in place (rich ``Live``); without one (a pipe) only the final screen is
printed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from rich.console import Console

from eyeq_spi.errors import UsageError
from eyeq_spi.monitor.model import Snapshot
from eyeq_spi.monitor.view import (
    new_live,
    print_whole,
    render,
    save_lines,
    screen_lines,
)

MIN_REFRESH, MAX_REFRESH = 5.0, 30.0
DEFAULT_REFRESH = 6.0  # a margin over the 5 Hz the monitor promises


class Source(Protocol):
    @property
    def done(self) -> bool: ...

    def advance(self, deadline: float) -> None: ...

    def snapshot(self) -> Snapshot: ...

    def close(self) -> None: ...


@dataclass
class RunStats:
    redraws: int = 0
    draw_cpu_s: float = 0.0  # CPU time spent building and writing screens (tools/bench_monitor)
    interrupted: bool = False  # stopped by Ctrl-C


SCREENSHOT_SUFFIXES = (".svg", ".html", ".txt")


def check_screenshot(path: str) -> None:
    if not path.lower().endswith(SCREENSHOT_SUFFIXES):
        raise UsageError(f"--screenshot {path}: the file must end in "
                         + ", ".join(SCREENSHOT_SUFFIXES))


def save_screen(snap: Snapshot, path: str, size: tuple[int, int] | None = None) -> None:
    """The screen of ``snap`` as an SVG picture, an HTML page or plain text (rich's export);
    ``size`` (columns, rows): as a terminal of that size shows it (default: the whole screen,
    as wide as it is)."""

    check_screenshot(path)
    lines = screen_lines(snap) if size is None else screen_lines(snap, size[0], size[1])
    save_lines(lines, path, f"eyeq-spi monitor: {snap.source}")


def run(source: Source, *, refresh: float = DEFAULT_REFRESH, console: Any = None,
        clock: Callable[[], float] = time.perf_counter,
        on_draw: Callable[[Snapshot], None] | None = None,
        screenshot: str | None = None,
        screenshot_size: tuple[int, int] | None = None) -> RunStats:
    """Run until the source is done (or Ctrl-C); returns how much CPU drawing took. With
    ``screenshot``, the last screen is also written there (:func:`save_screen`)."""
    if not MIN_REFRESH <= refresh <= MAX_REFRESH:
        raise UsageError(f"--refresh must be {MIN_REFRESH:g}..{MAX_REFRESH:g} Hz")
    if screenshot is not None:
        check_screenshot(screenshot)
    console = console or Console()
    period = 1.0 / refresh
    stats = RunStats()
    live_screen = console.is_terminal
    live = new_live(console)
    snap: Snapshot | None = None
    try:
        if live_screen:
            live.start()
        next_draw = clock()
        try:
            while True:
                source.advance(next_draw)
                cpu_start = time.process_time()
                snap = source.snapshot()
                if on_draw is not None:
                    on_draw(snap)
                if live_screen:
                    live.update(render(snap, console.width, console.height), refresh=True)
                stats.redraws += 1
                stats.draw_cpu_s += time.process_time() - cpu_start
                if source.done:
                    break
                # keep the redraw grid: a slightly late draw is caught up, a whole missed
                # period is skipped (never a burst of draws)
                next_draw += period
                if clock() - next_draw > period:
                    next_draw = clock()
        except KeyboardInterrupt:  # Ctrl-C is the way to stop a live view: a normal end
            stats.interrupted = True
            snap = source.snapshot()
            if live_screen:
                live.update(render(snap, console.width, console.height), refresh=True)
    finally:
        if live_screen:
            live.stop()
        source.close()
    if screenshot is not None and snap is not None:
        save_screen(snap, screenshot, screenshot_size)
    if not live_screen and snap is not None:
        print_whole(console, screen_lines(snap))  # a pipe: the final screen
    return stats
