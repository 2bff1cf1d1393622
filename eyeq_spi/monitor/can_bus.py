"""``eyeq-spi monitor --can-bus INTERFACE:CHANNEL``: one line per frame ID with its message,
count, cycle time against the spec and newest signals, as ``cantools monitor``.
:class:`CanBusView` is sans-IO (``add(msg, now)``, ``lines(width, height)``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rich.console import Console, Group
from rich.text import Text

from eyeq_spi.monitor.view import new_live, print_whole, save_lines


@dataclass
class _Row:
    name: str | None
    count: int = 0
    last: float | None = None
    cycle_ms: float | None = None  # smoothed interval
    spec_ms: float | None = None
    rec: dict[str, Any] = field(default_factory=dict)
    errors: int = 0


class CanBusView:
    """Frames per (channel, ID), cycle times and the newest decoded values."""

    def __init__(self, proto: str, source: str) -> None:
        from eyeq_spi.can.decode import CanDecoder

        self.decoder = CanDecoder(proto)
        self.source = source
        self.rows: dict[tuple[str | None, int], _Row] = {}
        self.frames = 0
        self.error_frames = 0
        self.now = 0.0
        self.done = False

    def add(self, msg: Any, now: float) -> None:
        self.now = now
        rec = self.decoder.decode(msg, self.frames)
        self.frames += 1
        key = (rec["header"]["channel"], rec["header"]["id"])
        row = self.rows.get(key)
        if row is None:
            spec = self.decoder.spec_for(key[1])
            row = self.rows[key] = _Row(rec["name"], spec_ms=spec.cycle_ms if spec else None)
        at = float(msg.timestamp) if msg.timestamp else now
        if row.last is not None and at > row.last:
            dt = (at - row.last) * 1000.0
            row.cycle_ms = dt if row.cycle_ms is None else 0.8 * row.cycle_ms + 0.2 * dt
        row.last = at
        row.count += 1
        row.rec = rec
        if rec["errors"]:
            row.errors += 1
            self.error_frames += 1

    def lines(self, width: int = 120, height: int | None = None) -> list[Any]:
        head = Text.assemble(("eyeq-spi monitor ", "bold"), (self.source, "cyan"),
                             f"   {self.decoder.protocol.name}   frames {self.frames}   ",
                             (f"errors {self.error_frames}",
                              "bold red" if self.error_frames else "green"),
                             ("   finished" if self.done else "", "dim"))
        out = [head, Text(f"{'ch':>4s} {'ID':>5s} {'message':22s} {'count':>7s} "
                          f"{'cycle':>6s} {'spec':>4s}  signals", style="bold")]
        for (ch, fid), row in sorted(self.rows.items(), key=lambda kv: (kv[0][1],
                                                                         str(kv[0][0]))):
            rec = row.rec
            cyc = "-" if row.cycle_ms is None else f"{row.cycle_ms:.0f}"
            spec = "-" if row.spec_ms is None else f"{row.spec_ms:g}"
            line = Text(f"{ch or '-':>4s} {fid:5X} {(row.name or '?')[:22]:22s} {row.count:7d} "
                        f"{cyc:>6s} {spec:>4s}  ")
            if rec["errors"]:  # first: a narrow terminal crops the signals, not the errors
                line.append("; ".join(rec["errors"]) + "  ", style="red")
            for key, value in rec["fields"].items():
                text = f"{value:.4g}" if isinstance(value, float) else str(value)
                label = rec["labels"].get(key)
                if label:
                    text = label
                line.append(f"{key}=")
                line.append(text, style="dim" if key in rec["invalid"] else "cyan")
                line.append(" ")
            line.truncate(width, overflow="crop")
            out.append(line)
        if height is not None and len(out) > height:
            more = len(out) - height + 1
            out = [*out[:height - 1], Text(f"... {more} more IDs (a taller terminal shows them)",
                                           style="dim")]
        return out


def run_can_monitor(target: str, proto: str, *, duration: float | None = None,
                    refresh: float = 6.0, console: Any = None,
                    clock: Callable[[], float] = time.monotonic,
                    screenshot: str | None = None) -> CanBusView:
    """Show the bus ``target`` until ``duration`` seconds have passed or Ctrl-C."""
    from eyeq_spi.can.logs import open_bus, read_bus
    from eyeq_spi.monitor.app import check_screenshot

    if screenshot is not None:
        check_screenshot(screenshot)
    console = console or Console()
    view = CanBusView(proto, target)
    bus = open_bus(target)
    live = new_live(console)
    start = clock()
    period = 1.0 / refresh
    on_terminal = console.is_terminal
    try:
        if on_terminal:
            live.start()
        while True:
            left = None if duration is None else start + duration - clock()
            if left is not None and left <= 0:
                break
            slot = period if left is None else min(period, left)
            for msg in read_bus(bus, duration=slot, now=clock, poll=min(0.05, slot)):
                view.add(msg, clock() - start)
            if on_terminal:
                live.update(Group(*view.lines(console.width, console.height)), refresh=True)
    except KeyboardInterrupt:  # Ctrl-C ends a live view normally
        pass
    finally:
        bus.shutdown()
        view.done = True
        if on_terminal:
            live.update(Group(*view.lines(console.width, console.height)), refresh=True)
            live.stop()
    if not on_terminal:  # a pipe: the final screen once
        print_whole(console, view.lines(width=400))
    if screenshot is not None:
        save_lines(view.lines(width=400), screenshot, f"eyeq-spi monitor: {view.source}")
    return view
