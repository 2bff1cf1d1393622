"""Replay the EyeQ channel of a capture to a host: a recorded drive as a stand-in EyeQ.

:class:`ReplayEyeQ` is a sans-IO node (docs/STYLE.md §2) that plays every transfer of the
capture's ``e2h`` channel at its capture time (relative to the first), byte for byte, except the
EyeQ's ACK/NAK frames: it answers the host in front of it itself, through a
:class:`TransportConnection` in the EyeQ role (L5); the host's ACK/NAKs are counted, not
checked (recorded frames are never resent, L7). ``replay_into_host`` runs it against the host
emulator in virtual time, ``replay_to_port`` in real time against a host at a pyserial URL.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.catalog.messages import sw_release_text as sw_text
from eyeq_spi.codec.message import DecodedMessage, MessageCodec
from eyeq_spi.errors import AdapterError, EyeqError, InputError, RemoteProtocolError
from eyeq_spi.link.connection import LinkConfig
from eyeq_spi.link.frame import FRAME_SIZE, FrameCodec, FrameKind
from eyeq_spi.transport.connection import TransportConnection
from eyeq_spi.transport.events import MessageReceived


class ReplayEyeQ:
    def __init__(self, transfers: Iterable[Transfer], *, start: float = 0.0,
                 duration: float | None = None, sw: str | None = None,
                 count_sent: bool = False) -> None:
        self._src: Iterator[Transfer] = (r for r in transfers if r.direction == "e2h")
        self.start = start
        self.duration = duration
        self.frames = FrameCodec()
        self.conn = TransportConnection(LinkConfig(role="eyeq"))
        self.codec = MessageCodec(sw)
        self.offset: float | None = None
        self._next: Transfer | None = None
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
        # count_sent: the played frames reassembled as the recorded host's driver did, so the
        # summary names the messages sent (``sent``); what it would answer is discarded
        self.sent: Counter[str] = Counter()
        self.decode_errors = 0
        self._played_rx = TransportConnection(LinkConfig(role="host")) if count_sent else None
        # on_message(message, now): every played message, decoded (count_sent only)
        self.on_message: Callable[[DecodedMessage, float], None] | None = None
        self._advance()
        if self._next is None:
            raise InputError("the capture has no e2h transfer (EyeQ channel) to replay")

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
        for transfer in self._src:
            if self._is_control(transfer.data):
                self.skipped_acks += 1  # they answered the recorded host, not this one
                continue
            time = self._last_at if transfer.time is None else transfer.time
            if self.offset is None:
                self.offset = self.start - time
            at = max(time + self.offset, self._last_at)
            if self.duration is not None and at > self.start + self.duration:
                break
            self._next, self._next_at = transfer, at
            return
        self._next = self._next_at = None
        self.done = True

    def _is_control(self, data: bytes) -> bool:
        if len(data) != FRAME_SIZE:
            return False
        try:
            frame = self.frames.decode(data)
        except RemoteProtocolError:
            return False
        return frame.kind in (FrameKind.ACK, FrameKind.NAK) and self.frames.crc_ok(data, frame)

    # -- Node ---------------------------------------------------------------------------
    def receive_data(self, transfer: bytes, now: float) -> None:
        if self._is_control(transfer):
            frame = self.frames.decode(transfer)
            if frame.kind is FrameKind.ACK:
                self.host_acks += 1
            else:
                self.host_naks[frame.num] += 1
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
            if self._played_rx is not None:
                self._count_sent(self._next.data, now)
            self.lateness_max = max(self.lateness_max, now - self._next_at)
            self._last_at = self._next_at
            self._advance()
        return out

    def _count_sent(self, transfer: bytes, now: float) -> None:
        rx = self._played_rx
        assert rx is not None
        try:
            rx.receive_data(transfer, now)
            rx.data_to_send(now)  # the ACKs it would send: not ours to send
            while (ev := rx.next_event()) is not None:
                if isinstance(ev, MessageReceived):
                    out = self.codec.decode(ev.data)
                    self.sent[out.name or out.protocol] += 1
                    if self.on_message is not None:
                        self.on_message(out, now)
        except EyeqError:
            self.decode_errors += 1

    def get_timer(self) -> float | None:
        timers = [t for t in (self._next_at, self.conn.get_timer()) if t is not None]
        return min(timers) if timers else None

    def handle_timer(self, now: float) -> None:
        timer = self.conn.get_timer()
        if timer is not None and timer <= now:
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
                "complete": self.done, "sw": self.codec.sw and sw_text(self.codec.sw),
                "decode_errors": self.decode_errors}


def host_bench(transfers: Iterable[Transfer], *, sw: str | None = None,
               duration: float | None = None) -> tuple[ReplayEyeQ, Any, Any]:
    """The capture's EyeQ channel wired to a started built-in host emulator on a
    :class:`VirtualRunner` (virtual time = capture time from its first transfer): (node, host,
    runner). Used by :func:`replay_into_host` and by ``eyeq-spi monitor --replay``."""
    from eyeq_spi.host.host import HostConfig, HostEmulator
    from eyeq_spi.phy.memory import memory_pair
    from eyeq_spi.runner.virtual import VirtualRunner

    node = ReplayEyeQ(transfers, duration=duration, sw=sw)
    host = HostEmulator(HostConfig(sw=sw), keep_rx_times=False, reset_line=node.reset_line)
    host_end, node_end = memory_pair()
    runner = VirtualRunner([(host, host_end), (node, node_end)])
    host.start(0.0)
    return node, host, runner


def replay_into_host(transfers: Iterable[Transfer], *, sw: str | None = None,
                     duration: float | None = None, realtime: bool = False,
                     on_host: Callable[[Any], None] | None = None) -> dict[str, Any]:
    """Feed the capture's EyeQ channel to the built-in host emulator in virtual time; the run
    summary (:mod:`eyeq_spi.summary`) checks it as ``host`` checks a live run: Running Vision
    reached and held, nothing lost (E2E, DASP counters, stale streams, MESP timeouts).
    ``realtime``: at the capture's pace (virtual time kept on the wall clock) instead of as
    fast as possible; ``on_host(host)``: called once with the host before the replay starts (a
    live view subscribes to it)."""
    import time

    from eyeq_spi.host.machine import HostState
    from eyeq_spi.summary import host_summary

    cpu0 = time.process_time()
    wall0 = time.monotonic()
    node, host, runner = host_bench(transfers, sw=sw, duration=duration)
    if on_host is not None:
        on_host(host)
    pace = (time.perf_counter(), runner.now) if realtime else None
    reached: float | None = None
    left: list[float] = []
    while not node.done:
        runner.run_until(runner.now + 0.01, realtime=realtime, pace_origin=pace)
        running = host.state is HostState.RUNNING_VISION
        if running and reached is None:
            reached = runner.now
        elif not running and reached is not None:
            left.append(runner.now)
            reached = None
    runner.run_until(runner.now + 0.05)  # let the last frames settle, well before stale limits
    out = host_summary(host, side="replay", elapsed=runner.now,
                       wall=time.monotonic() - wall0, cpu=time.process_time() - cpu0,
                       running_since=reached, left_running=left)
    out["replay"] = node.summary()
    return out


def replay_to_port(transfers: Iterable[Transfer], url: str, *, listen: bool = False,
                   duration: float | None = None, connect_timeout: float = 30.0,
                   lead: float = 0.5, sw: str | None = None,
                   on_message: Callable[[DecodedMessage, float], None] | None = None,
                   ) -> dict[str, Any]:
    """Play the capture's EyeQ channel to a host under test in real time: connect to it at
    ``url`` (``listen``: listen on ``url``, ``tcp://HOST:PORT``, and wait for it), starting
    ``lead`` seconds after the connection: a host opening its port may discard what arrives
    meanwhile (pyserial's ``socket://`` resets its input buffer on open).
    ``on_message(message, now)``: every message played, decoded (a live view)."""
    import sys
    import time

    from eyeq_spi.errors import LinkLostError
    from eyeq_spi.phy.base import open_listener, open_url
    from eyeq_spi.runner.realtime import RealTimeRunner
    from eyeq_spi.summary import link_view, replay_port_summary

    node = ReplayEyeQ(transfers, duration=duration, sw=sw, count_sent=True)
    node.on_message = on_message
    adapter = open_listener(url, timeout=connect_timeout) if listen else open_url(url)
    address = getattr(adapter, "url", url)
    lost: str | None = None
    interrupted = False
    cpu0 = time.process_time()
    t0 = time.monotonic()
    try:
        if listen:  # the capture starts when the host is there
            print(f"LISTEN {address}", file=sys.stderr, flush=True)
            print(f"replay: waiting for the host at {address}", file=sys.stderr, flush=True)
            if not adapter.accept(connect_timeout):  # type: ignore[attr-defined]
                raise AdapterError(f"no host connected to {address} within {connect_timeout} s")
        runner = RealTimeRunner(node, adapter)
        t0 = time.monotonic()
        node.begin(t0 + lead)
        try:
            runner.run(stop=lambda: node.done)
            # the host's last answers: until every played frame is answered, at most 1 s
            runner.run(1.0, stop=lambda: node.host_acks + node.host_naks.total() >= node.played)
        except LinkLostError as exc:
            lost = str(exc)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            runner.close()
    finally:
        adapter.close()
    rep = node.summary()
    rep["max_lateness_ms"] = round(node.lateness_max * 1e3, 3)
    return replay_port_summary(rep, address=address, wall=time.monotonic() - t0,
                               cpu=time.process_time() - cpu0,
                               link=link_view(node.conn.link.counters), link_lost=lost,
                               sent=dict(sorted(node.sent.items())), interrupted=interrupted)
