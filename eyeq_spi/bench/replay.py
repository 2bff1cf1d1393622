"""Replay the EyeQ channel of a capture to a host: a recorded drive as a stand-in EyeQ.

:class:`ReplayEyeQ` is a sans-IO node (``receive_data``/``data_to_send``/``get_timer``/
``handle_timer``, docs/STYLE.md §2). It plays every transfer of the capture's ``e2h`` channel at its
capture time, byte for byte, except the EyeQ's ACK/NAK frames: those answered the recorded host,
so the node answers the host in front of it instead, through a real :class:`TransportConnection`
in the EyeQ role (ACK every accepted frame, NAK per L5, reassemble the host's messages to count
them). The host's ACK/NAK frames for the played frames are counted, not judged: the recorded
frames are never resent (L7).

Time: the replay clock is the capture's time minus its first transfer's time, plus the moment
the replay starts. ``replay_into_host`` runs it against the built-in host emulator on the
:class:`VirtualRunner` (virtual time, no reset line: the host's own logic judges states, E2E,
DASP counters and stale streams); ``replay_to_port`` runs it on the :class:`RealTimeRunner`
against a host under test at a pyserial URL. The capture is read lazily: memory stays bounded.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Iterator
from typing import Any

from eyeq_spi.capture.pcapng_io import Record
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.errors import EyeqError, FrameError
from eyeq_spi.link.connection import LinkConfig
from eyeq_spi.link.frame import FRAME_SIZE, FrameCodec, FrameKind
from eyeq_spi.transport.connection import TransportConnection
from eyeq_spi.transport.events import MessageReceived


class ReplayError(EyeqError):
    """A capture cannot be replayed (no EyeQ channel in it...)."""


class ReplayEyeQ:
    def __init__(self, records: Iterable[Record], *, start: float = 0.0,
                 duration: float | None = None, sw: str | None = None) -> None:
        self._src: Iterator[Record] = (r for r in records if r.direction == "e2h")
        self.start = start
        self.duration = duration
        self.frames = FrameCodec()
        self.conn = TransportConnection(LinkConfig(role="eyeq"))
        self.codec = MessageCodec(sw)
        self.offset: float | None = None
        self._next: Record | None = None
        self._next_at: float | None = None
        self._last_at = start
        self.played = 0
        self.skipped_acks = 0
        self.host_acks = 0
        self.host_naks: Counter[int] = Counter()
        self.host_messages: Counter[str] = Counter()
        self.lateness_max = 0.0
        self.resets = 0
        self.acks_sent = 0
        self.done = False
        self._advance()
        if self._next is None:
            raise ReplayError("the capture has no e2h transfer (EyeQ channel) to replay")

    def begin(self, now: float) -> None:
        """Start the replay clock at ``now`` (after slow set-up such as loading the specs)."""
        shift = now - self.start
        self.start = now
        self._last_at += shift
        if self.offset is not None:
            self.offset += shift
        if self._next_at is not None:
            self._next_at += shift

    # -- the capture --------------------------------------------------------------------
    def _advance(self) -> None:
        for rec in self._src:
            if self._is_control(rec.data):
                self.skipped_acks += 1  # they answered the recorded host, not this one
                continue
            t = self._last_at if rec.time is None else rec.time
            if self.offset is None:
                self.offset = self.start - t
            at = max(t + self.offset, self._last_at)
            if self.duration is not None and at > self.start + self.duration:
                break
            self._next, self._next_at = rec, at
            return
        self._next = self._next_at = None
        self.done = True

    def _is_control(self, data: bytes) -> bool:
        if len(data) != FRAME_SIZE:
            return False
        try:
            f = self.frames.decode(data)
        except FrameError:
            return False
        return f.kind in (FrameKind.ACK, FrameKind.NAK) and self.frames.crc_ok(data, f)

    # -- Node ---------------------------------------------------------------------------
    def receive_data(self, transfer: bytes, now: float) -> None:
        if self._is_control(transfer):
            f = self.frames.decode(transfer)
            if f.kind is FrameKind.ACK:
                self.host_acks += 1
            else:
                self.host_naks[f.num] += 1
            return
        self.conn.receive_data(transfer, now)
        while (ev := self.conn.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                out = self.codec.decode(ev.data)
                self.host_messages[out.name or out.protocol] += 1

    def data_to_send(self, now: float) -> list[bytes]:
        out = self.conn.data_to_send(now)
        self.acks_sent += len(out)  # our link sends nothing but ACK/NAK frames
        while self._next is not None and self._next_at is not None and self._next_at <= now:
            out.append(self._next.data)
            self.played += 1
            self.lateness_max = max(self.lateness_max, now - self._next_at)
            self._last_at = self._next_at
            self._advance()
        return out

    def get_timer(self) -> float | None:
        timers = [t for t in (self._next_at, self.conn.get_timer()) if t is not None]
        return min(timers) if timers else None

    def handle_timer(self, now: float) -> None:
        t = self.conn.get_timer()
        if t is not None and t <= now:
            self.conn.handle_timer(now)

    def reset_line(self, now: float) -> None:
        """The host pulled the reset line: the capture already holds what the EyeQ did next
        (its reboot), so only our SPI driver starts over, as the recorded EyeQ's did (L4)."""
        self.resets += 1
        self.conn = TransportConnection(LinkConfig(role="eyeq"))

    def summary(self) -> dict[str, Any]:
        return {"played": self.played, "eyeq_acks_not_replayed": self.skipped_acks,
                "acks_sent": self.acks_sent,
                "host_acks": self.host_acks,
                "host_naks": {f"0x{k:03X}": v for k, v in sorted(self.host_naks.items())},
                "host_messages": dict(sorted(self.host_messages.items())),
                "reset_line_pulls": self.resets,
                "complete": self.done}


def host_bench(records: Iterable[Record], *, sw: str | None = None,
               duration: float | None = None) -> tuple[ReplayEyeQ, Any, Any]:
    """The capture's EyeQ channel wired to a started built-in host emulator on a
    :class:`VirtualRunner` (virtual time = capture time from its first transfer): (node, host,
    runner). Used by :func:`replay_into_host` and by ``eyeq-spi monitor --replay``."""
    from eyeq_spi.host.host import HostConfig, HostEmulator
    from eyeq_spi.phy.memory import memory_pair
    from eyeq_spi.runner.virtual import VirtualRunner

    node = ReplayEyeQ(records, duration=duration, sw=sw)
    host = HostEmulator(HostConfig(sw=sw), keep_rx_times=False, reset_line=node.reset_line)
    a, b = memory_pair()
    runner = VirtualRunner([(host, a), (node, b)])
    host.start(0.0)
    return node, host, runner


def replay_into_host(records: Iterable[Record], *, sw: str | None = None,
                     duration: float | None = None) -> dict[str, Any]:
    """Feed the capture's EyeQ channel to the built-in host emulator in virtual time."""
    from eyeq_spi.host.machine import HostState

    node, host, runner = host_bench(records, sw=sw, duration=duration)
    reached: float | None = None
    while not node.done:
        runner.run_until(runner.now + 0.01)
        if reached is None and host.state is HostState.RUNNING_VISION:
            reached = runner.now
    runner.run_until(runner.now + 0.05)  # let the last frames settle, well before stale limits
    link = host.conn.link.counters.seed_view()
    out: dict[str, Any] = {
        "mode": "into-host", "virtual_s": round(runner.now, 6), "state": host.state.value,
        "running_vision_at": None if reached is None else round(reached, 4),
        "transitions": [{"t": round(t.time, 4), "from": t.src.value, "event": t.event.value,
                         "to": t.dst.value} for t in host.transitions],
        "messages": dict(sorted((k, int(v)) for k, v in host.counters.received.items())),
        "e2e_errors": host.counters.e2e_errors,
        "dasp_counter_gaps": host.counters.dasp_counter_gaps,
        "decode_errors": host.counters.decode_errors,
        "stale_events": dict(sorted(host.counters.stale_events.items())),
        "link": link, "problem": host.problem, "replay": node.summary(),
    }
    out["ok"] = bool(reached is not None and not out["e2e_errors"] and not out["decode_errors"]
                     and host.state is HostState.RUNNING_VISION)
    return out


def replay_to_port(records: Iterable[Record], url: str, *, duration: float | None = None,
                   connect_timeout: float = 30.0, lead: float = 0.5) -> dict[str, Any]:
    """Play the capture's EyeQ channel to a host under test at ``url`` in real time, starting
    ``lead`` seconds after the connection: a host opening its port may discard what arrives
    meanwhile (pyserial's ``socket://`` resets its input buffer on open)."""
    import sys
    import time

    from eyeq_spi.errors import LinkLostError
    from eyeq_spi.phy.base import open_url
    from eyeq_spi.runner.realtime import RealTimeRunner

    adapter = open_url(url, timeout=connect_timeout)
    lost: str | None = None
    try:
        accept = getattr(adapter, "accept", None)
        if accept is not None:  # a listener: the capture starts when the host is there
            print(f"replay: waiting for the host at {getattr(adapter, 'url', url)}",
                  file=sys.stderr, flush=True)
            if not accept(connect_timeout):
                raise ReplayError(f"no host connected to {url} within {connect_timeout} s")
        node = ReplayEyeQ(records, duration=duration)
        runner = RealTimeRunner(node, adapter)
        t0 = time.monotonic()
        node.begin(t0 + lead)
        try:
            runner.run(stop=lambda: node.done)
            # the host's last answers: until every played frame is answered, at most 1 s
            runner.run(1.0, stop=lambda: node.host_acks + node.host_naks.total() >= node.played)
        except LinkLostError as exc:
            lost = str(exc)
        wall = time.monotonic() - t0
    finally:
        adapter.close()
    out = {"mode": "port", "url": url, "wall_s": round(wall, 3),
           "max_lateness_ms": round(node.lateness_max * 1e3, 3), **node.summary(),
           "link_lost": lost}
    out["ok"] = node.done and lost is None
    return out
