"""Where the monitor's data comes from: each source advances until a wall-clock deadline (the
next redraw), then describes itself as a :class:`Snapshot`. The demo, host and replay sources
read the host only through its public face (``subscribe``, ``subscribe_traffic``, ``state``,
``transitions``, its counters); :class:`DissectSource` (``--passive``) reads both channels of a
capture through the dissector, for captures without the EyeQ's bring-up.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from eyeq_spi.codec.message import DecodedMessage, MessageCodec
from eyeq_spi.dissect.pipeline import CaptureFile, DissectConfig, open_capture_file
from eyeq_spi.foxglove.live import link_counts
from eyeq_spi.interop.replay import host_bench
from eyeq_spi.monitor.model import RateMeter, Snapshot
from eyeq_spi.plot.collect import frame_counters
from eyeq_spi.plot.perceived import SCENE_MESSAGES, Labels, SceneTracker

Clock = Callable[[], float]
MAIN_STATE_MSG = "EYEQ_DIAGNOSTIC_MSG"  # 0x41
CATCH_UP = 0.05  # s of virtual time per slice (about 15 ms of CPU): trailing the wall clock,
# or in virtual time, the source looks at the redraw deadline between slices


class _HostView:
    """Snapshot of a HostEmulator through its public face."""

    def __init__(self, host: Any, source: str, origin: float = 0.0) -> None:
        self.host = host
        self.source = source
        self.origin = origin  # the host's clock reading at the snapshots' time 0
        self.rates = RateMeter(host.codec.cat)
        self.tracker = SceneTracker(Labels(host.codec))
        self._latest: dict[str, DecodedMessage] = {}
        host.subscribe(self._on_message)
        host.subscribe_traffic(self._on_traffic)

    def _on_message(self, out: DecodedMessage) -> None:
        # keep only the latest scene message of each kind; decoding it into a scene waits for
        # the next redraw, so the link path pays one dict store per message
        if out.name in SCENE_MESSAGES:
            self._latest[out.name] = out

    def _on_traffic(self, name: str, now: float) -> None:
        self.rates.arrived(name, now - self.origin)  # received, or sent by the host

    def snapshot(self, now: float, done: bool) -> Snapshot:
        host = self.host
        counts: Counter[str] = Counter(host.counters.received)
        counts["HOST_VEH_STATE_MSG"] = host.counters.sent.get("HOST_VEH_STATE_MSG", 0)
        self.rates.tick(now, counts)
        for name, out in self._latest.items():
            self.tracker.update(name, out.fields, now, out.errors)
        self._latest.clear()
        link = link_counts(host, "abort")
        counters = host.counters
        errors = {"E2E errors": counters.e2e_errors,
                  "DASP counter gaps": counters.dasp_counter_gaps,
                  "decode errors": counters.decode_errors,
                  # every reset: the host's own and those it detected (the summary splits them)
                  "EyeQ resets": counters.eyeq_resets_asked + counters.eyeq_resets,
                  "MESP timeouts": host.mesp.counters.timeouts}
        trans = [(t.time - self.origin, t.src.value, t.event.value, t.dst.value)
                 for t in host.transitions[-8:]]
        return Snapshot(self.source, now, "host state", host.state.value, trans,
                        self.rates.rows(), link, errors, sorted(host.stale_streams),
                        self.tracker.snapshot(), host.problem, done,
                        transitions_seen=len(host.transitions))


class DemoSource:
    """An in-process emulation (``emu``: ``host``, ``runner.now``, ``run_for``) whose virtual
    time is kept on the wall clock times ``speed`` from the start."""

    def __init__(self, emu: Any, duration: float, *, realtime: bool = True,
                 clock: Clock = time.perf_counter, sleep: Callable[[float], None] = time.sleep,
                 speed: float = 1.0, label: str = "demo",
                 on_close: Callable[[], None] | None = None) -> None:
        self.emu = emu
        self.on_close = on_close
        self.duration = duration
        self.realtime = realtime
        self.speed = speed
        self.clock, self.sleep = clock, sleep
        self.view = _HostView(emu.host, label + ("" if realtime else " (virtual time)"))
        self.start = clock()

    @property
    def done(self) -> bool:
        return bool(self.emu.runner.now >= self.duration - 1e-9)

    def advance(self, deadline: float) -> None:
        emu = self.emu
        while not self.done and self.clock() < deadline:
            if self.realtime:
                target = min(self.duration, (self.clock() - self.start) * self.speed)
                if target > emu.runner.now:
                    # virtual time catches up the wall in slices of at most CATCH_UP s, so a
                    # machine that cannot keep up still sees the redraw deadline on time
                    emu.run_for(min(target - emu.runner.now, CATCH_UP))
                else:
                    self.sleep(min(0.002 / self.speed, max(0.0, deadline - self.clock())))
            else:
                emu.run_for(min(CATCH_UP, self.duration - emu.runner.now))

    def snapshot(self) -> Snapshot:
        return self.view.snapshot(self.emu.runner.now, self.done)

    def close(self) -> None:
        if self.on_close is not None:
            self.on_close()


class HostSource:
    def __init__(self, host: Any, runner: Any, duration: float | None, *,
                 on_close: Callable[[], None] | None = None) -> None:
        self.host = host
        self.runner = runner
        self.duration = duration
        self.on_close = on_close
        self.start = runner.clock()
        self.view = _HostView(host, "host", origin=self.start)
        host.start(self.start)

    @property
    def now(self) -> float:
        return float(self.runner.clock() - self.start)

    @property
    def done(self) -> bool:
        from eyeq_spi.host.machine import HostState

        over = self.duration is not None and self.now >= self.duration
        return over or self.host.state in (HostState.FAILED, HostState.BOOT_FAILED)

    def advance(self, deadline: float) -> None:
        while not self.done and time.perf_counter() < deadline:
            self.runner.step()

    def snapshot(self) -> Snapshot:
        return self.view.snapshot(self.now, self.done)

    def close(self) -> None:
        if self.on_close is not None:
            self.on_close()


class _ReplayBench:
    """The replay's node, host and virtual runner with the ``emu`` face DemoSource drives."""

    def __init__(self, transfers: Iterable[Any], sw: str | None, duration: float | None) -> None:
        self.node, self.host, self.runner = host_bench(transfers, sw=sw, duration=duration)

    def run_for(self, dt: float) -> None:
        self.runner.run_until(self.runner.now + dt)


class ReplaySource(DemoSource):
    """A capture replayed into the host emulator (``eyeq-spi replay --into-host``), in capture
    time: the snapshot's ``now`` is the capture's time from its first transfer. ``speed`` is
    times real time; 0 runs as fast as possible. It is done SETTLE s after the last frame."""

    SETTLE = 0.05  # as replay_into_host: the last frames settle, well before stale limits

    def __init__(self, path: str | CaptureFile, *, sw: str | None = None, speed: float = 1.0,
                 fmt: str | None = None, duration: float | None = None,
                 clock: Clock = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        """``path``: a capture file (any format the dissect pipeline reads), or one the
        pipeline opened; its EyeQ channel is replayed as the release it is read with."""
        self.capture = path if isinstance(path, CaptureFile) else open_capture_file(
            path, DissectConfig(fmt=fmt, sw=sw, pace_gc=False))
        self.tail = self.capture.tail  # what was left at the end of a pcapng cut inside a block
        try:
            self.bench = _ReplayBench(self.capture.transfers, self.capture.release.key,
                                      duration)
        except BaseException:
            self.capture.close()
            raise
        path = self.capture.path
        name = f"replay {Path(path).name}" + ("" if speed in (0, 1) else f" x{speed:g}")
        super().__init__(self.bench, math.inf, realtime=speed > 0, clock=clock, sleep=sleep,
                         speed=speed or 1.0, label=name)
        self._end: float | None = None

    @property
    def done(self) -> bool:
        if not self.bench.node.done:
            return False
        if self._end is None:
            self._end = float(self.bench.runner.now)
        return bool(self.bench.runner.now >= self._end + self.SETTLE - 1e-9)

    def close(self) -> None:
        self.capture.close()


class DissectSource:
    """A capture at its own pace through the dissector (both channels as recorded): record times
    (from the first one) against the wall clock times ``speed``. Records without times (raw,
    hex without times) are fed as fast as possible."""

    def __init__(self, path: str | CaptureFile, codec: MessageCodec, *, speed: float = 1.0,
                 fmt: str | None = None, clock: Clock = time.perf_counter) -> None:
        """``path``: a capture file (any format the dissect pipeline reads, dissected with
        ``codec``'s release), or one the pipeline opened."""
        self.capture = path if isinstance(path, CaptureFile) else open_capture_file(
            path, DissectConfig(fmt=fmt, sw=codec.sw, pace_gc=False))
        self.path = self.capture.path
        self.codec = codec
        self.speed = speed
        self.clock = clock
        self.tail = self.capture.tail  # what was left at the end of a pcapng cut inside a block
        self._records: Iterator[dict[str, Any]] = self.capture.items
        self._pending: dict[str, Any] | None = None
        self._t0: float | None = None
        self.start = clock()
        self.now = 0.0
        self.done = False
        self.rates = RateMeter(codec.cat)
        self.tracker = SceneTracker(Labels(codec))
        self.counts: Counter[str] = Counter()
        self.link: Counter[str] = Counter()
        self.errors: Counter[str] = Counter()
        self.state = "-"
        self.transitions: list[tuple[float, str, str, str]] = []
        self.transitions_seen = 0
        self.on_record: Callable[[dict[str, Any]], None] | None = None  # every record, as read

    def _next(self) -> dict[str, Any] | None:
        if self._pending is None:
            self._pending = next(self._records, None)
            if self._pending is None:
                self.done = True
        return self._pending

    def advance(self, deadline: float) -> None:
        while not self.done and self.clock() < deadline:
            record = self._next()
            if record is None:
                return
            time_s = record.get("time")
            if time_s is not None:
                if self._t0 is None:
                    self._t0 = time_s
                rel = time_s - self._t0
                if self.speed > 0 and rel > (self.clock() - self.start) * self.speed:
                    wait = self.start + rel / self.speed - self.clock()
                    time.sleep(max(0.0, min(wait, deadline - self.clock(), 0.01)))
                    continue
                self.now = rel
            self._pending = None
            self._add(record)

    def _add(self, record: dict[str, Any]) -> None:
        if self.on_record is not None:
            self.on_record(record)
        kind = record["kind"]
        if kind == "frame":
            self.link.update(frame_counters(record))
        elif kind == "event":
            key = (f"abort: {record['reason']}" if record["type"] == "transfer_aborted"
                   else record["type"])
            self.link[key] += 1
        else:
            name = record["name"] or record["protocol"]
            self.counts[name] += 1
            self.rates.arrived(name, self.now)
            for error in record["errors"]:
                key = ("E2E errors" if error.startswith("E2E") else "DASP counter gaps"
                       if error.startswith("DASP counter") else "decode errors")
                self.errors[key] += 1
            self.tracker.update(record["name"], record["fields"], self.now, record["errors"])
            if record["name"] == MAIN_STATE_MSG and not record["errors"]:
                self._main_state(record["fields"])

    def _main_state(self, fields: dict[str, Any]) -> None:
        state = fields.get("Main_State")
        label = self.tracker.labels.label(MAIN_STATE_MSG, ("Main_State",), state)
        if label != self.state:
            self.transitions.append((self.now, self.state, "0x41", label))
            self.transitions = self.transitions[-8:]
            self.transitions_seen += 1
            self.state = label

    def snapshot(self) -> Snapshot:
        self.rates.tick(self.now, self.counts)
        errors = {"E2E errors": 0, "DASP counter gaps": 0, "decode errors": 0, **self.errors}
        pace = "" if self.speed == 1 else " (as fast as possible)" if self.speed == 0 else (
            f" x{self.speed:g}")
        return Snapshot(f"dissect {Path(self.path).name}{pace}",
                        self.now, "EyeQ Main_State (0x41)", self.state, list(self.transitions),
                        self.rates.rows(), dict(self.link), errors, [],
                        self.tracker.snapshot(), None, self.done,
                        transitions_seen=self.transitions_seen)

    def close(self) -> None:
        close = getattr(self._records, "close", None)
        if close is not None:
            close()
        self.capture.close()
