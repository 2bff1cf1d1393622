"""One pass over a capture through the dissect pipeline, collecting what the plots draw.

Times are seconds from the capture's first timestamped transfer. Memory is bounded by what is
drawn: one float per periodic message for the timing plot, one counter per time bin for the link
plot, one scene per animation frame (and at most ``max_frames`` of them).
"""

from __future__ import annotations

import itertools
import math
from array import array
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi import garbage
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect.pipeline import CaptureFile, DissectConfig, open_capture_file
from eyeq_spi.errors import InputError, UsageError
from eyeq_spi.logic.options import SpiOptions
from eyeq_spi.plot.perceived import Labels, Scene, SceneTracker

GAP_PERIODS = 3.0  # a stream is stopped after 3 nominal periods of silence, the host's stale rule


def frame_counters(record: dict[str, Any]) -> list[str]:
    """The link counters a frame record counts in (plot --link, monitor): its direction and
    type, and its fault."""
    keys = [f"{record['direction'] or '?'} {record['frame_type']}"]
    if "length" in record:
        keys.append("wrong length")
    elif not record["crc_ok"]:
        keys.append("CRC errors")
    elif record["frame_type"] == "NAK":
        keys.append(f"NAK 0x{record['nak_reason']:03X}")
    return keys


@dataclass
class Window:
    """The part of the capture to draw, in seconds from its start (``--start``/``--end``)."""

    start: float = 0.0
    end: float = math.inf
    t0: float | None = None  # absolute time of the capture's first timestamp

    def rel(self, time_s: float | None) -> float | None:
        if time_s is None:
            return None
        if self.t0 is None:
            self.t0 = time_s
        return time_s - self.t0


@dataclass
class Stream:
    name: str
    direction: str | None
    rate_hz: float | None
    tolerance_ms: tuple[float, float] | None
    times: array[float] = field(default_factory=lambda: array("d"))
    counter_jumps: list[float] = field(default_factory=list)
    e2e_errors: list[float] = field(default_factory=list)

    @property
    def period(self) -> float | None:
        return 1.0 / self.rate_hz if self.rate_hz else None

    def gaps(self, end: float) -> list[tuple[float, float]]:
        """Silences longer than GAP_PERIODS periods, the one before ``end`` included."""
        period = self.period
        if period is None or not self.times:
            return []
        limit = GAP_PERIODS * period
        out = [(a, b) for a, b in itertools.pairwise(self.times) if b - a > limit]
        if end - self.times[-1] > limit:
            out.append((self.times[-1], end))
        return out


@dataclass
class Collected:
    window: Window
    end: float = 0.0  # last time seen (relative)
    streams: dict[str, Stream] = field(default_factory=dict)
    link_bin: float = 0.1
    link: dict[int, Counter[str]] = field(default_factory=dict)
    frames: list[Scene] = field(default_factory=list)
    scene: Scene | None = None
    has_time: bool = False


class Collector:
    """Feed it dissector records; ask for what you need at construction."""

    def __init__(self, codec: MessageCodec, window: Window, *, timing: bool = False,
                 link: bool = False, link_bin: float = 0.1, at: float | None = None,
                 fps: float | None = None, max_frames: int = 600) -> None:
        self.codec = codec
        self.cat = codec.cat
        self.window = window
        self.timing, self.link = timing, link
        self.at, self.fps, self.max_frames = at, fps, max_frames
        self.tracker = SceneTracker(Labels(codec)) if (at is not None or fps) else None
        self.out = Collected(window, link_bin=link_bin)
        self._next_frame = window.start
        self._last_t: float | None = None
        self.done = False

    def add(self, record: dict[str, Any]) -> None:
        time_s = self.window.rel(record.get("time"))
        if time_s is None and record["kind"] == "event":
            time_s = self._last_t  # an event names the frame that caused it (index), not its time
        elif time_s is not None:
            self._last_t = time_s
        if time_s is not None:
            self.out.has_time = True
            if self.tracker is not None:
                self._frames(time_s)
            if time_s > self.window.end:
                self.done = True
                return
            self.out.end = max(self.out.end, time_s)
            if time_s < self.window.start:
                if self.tracker is not None and record["kind"] == "message":
                    self.tracker.update(record["name"], record["fields"], time_s, record["errors"])
                return
        kind = record["kind"]
        if kind == "message":
            self._message(record, time_s)
        elif self.link and time_s is not None:
            self._link(record, time_s)

    def _frames(self, time_s: float) -> None:
        assert self.tracker is not None
        if self.at is not None:
            if time_s > self.at and self.out.scene is None:
                self.out.scene = self.tracker.snapshot()
                self.done = not (self.timing or self.link)
            return
        assert self.fps
        while time_s >= self._next_frame and self._next_frame <= self.window.end:
            if len(self.out.frames) >= self.max_frames:
                raise UsageError(f"more than {self.max_frames} animation frames: lower --fps, "
                                 "narrow --start/--end or raise --max-frames")
            snap = self.tracker.snapshot()
            snap.time = self._next_frame
            self.out.frames.append(snap)
            self._next_frame += 1.0 / self.fps

    def _message(self, record: dict[str, Any], time_s: float | None) -> None:
        name = record["name"]
        if self.tracker is not None:
            self.tracker.update(name, record["fields"], time_s, record["errors"])
        if not self.timing or time_s is None or record["protocol"] not in ("DASP", "DIAG"):
            return
        stream = self.out.streams.get(name)
        if stream is None:
            try:
                msg = self.cat.message(name)
            except Exception:
                return
            stream = Stream(name, record["direction"], msg.rate_hz, msg.tolerance_ms)
            self.out.streams[name] = stream
        stream.times.append(time_s)
        for error in record["errors"]:
            if error.startswith("DASP counter gap"):
                stream.counter_jumps.append(time_s)
            elif error.startswith("E2E"):
                stream.e2e_errors.append(time_s)
        if self.link:
            e2e = sum(error.startswith("E2E") for error in record["errors"])
            self._count(time_s, "E2E errors", e2e)

    def _count(self, time_s: float, key: str, count: int = 1) -> None:
        if count:
            link_bin = int(time_s // self.out.link_bin)
            counts = self.out.link.get(link_bin)
            if counts is None:  # not setdefault: a Counter built per frame cost a tenth
                counts = self.out.link[link_bin] = Counter()
            counts[key] += count

    def _link(self, record: dict[str, Any], time_s: float) -> None:
        if record["kind"] == "frame":
            for key in frame_counters(record):
                self._count(time_s, key)
        elif record["type"] == "transfer_aborted":
            self._count(time_s, f"abort: {record['reason']}")

    def finish(self) -> Collected:
        if self.tracker is not None:
            if self.at is not None and self.out.scene is None:
                self.out.scene = self.tracker.snapshot()  # --at past the end: the last scene
            elif self.fps and not self.out.frames:
                self.out.frames.append(self.tracker.snapshot())
        return self.out


def collect(path: str, collector: Collector, *, spi: SpiOptions | None = None) -> Collected:
    """The capture file ``path`` (any format :mod:`eyeq_spi.dissect.pipeline` reads) through
    ``collector``, dissected with the collector's release."""
    cf = open_capture_file(path, DissectConfig(spi=spi, sw=collector.codec.sw))
    try:
        return collect_capture(cf, collector)
    finally:
        cf.close()


def collect_capture(cf: CaptureFile, collector: Collector) -> Collected:
    """An opened capture's records through ``collector`` (the fast path where it applies),
    until the collector is done."""
    items = cf.items
    try:
        with garbage.paused():
            for record in items:
                collector.add(record)
                if collector.done:
                    break
    finally:
        close = getattr(items, "close", None)
        if close is not None:
            close()
    out = collector.finish()
    at_time = collector.at is not None and math.isfinite(collector.at)
    if not out.has_time and (collector.timing or collector.link or collector.fps or at_time):
        raise InputError(f"{cf.path}: the capture has no timestamps (a raw file, or hex without "
                         "times); this plot needs them")
    return out
