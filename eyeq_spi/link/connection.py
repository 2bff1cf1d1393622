"""Sans-IO link connection, one per side (seed 004 §6, decisions L4-L10).

Theory of operation
-------------------
``receive_data(transfer, now)`` judges one 128-byte transfer, in this order:

1. length (L8): not 128 bytes -> dropped, ``formatErrorCounter``, no NAK;
2. CRC (L3): mismatch -> ``dataCRCErrorCounter``; a DATA (or unknown-kind) frame is NAKed 0x002,
   a broken ACK/NAK is never answered;
3. D and R (L2): invalid -> ``formatErrorCounter``, NAK 0x011 (not for ACK/NAK);
4. ACK/NAK frames settle the sender's in-flight frames;
5. DATA frames go through the receive window (L6, L6a). A NUM in ``[E-W, E)`` is a duplicate
   if that NUM was accepted with the same bytes (ACK again, drop), a peer reset if it was
   accepted with other bytes (``Resynchronised(cause="peer_reset")``, then accept), a late
   frame if it was skipped (NAK 0x001, drop); the last W accepted transfers tell them apart.
   Out of window -> NAK 0x001 (resynchronise after 3 in a row), else the transport's payload
   check (NAK 0x011), then accept: ACK, ``DataReceived``.

``handle_timer(now)`` fails frames not ACKed within ``ack_timeout`` and frames not sent within
``transmit_timeout``: a lost frame is never resent, its tag fails once and its queued frames are
dropped. The rest is in docs/architecture.md ("Link layer") and docs/PROTOCOL_DECISIONS.md.
"""

from __future__ import annotations

from collections import Counter, OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

from eyeq_spi.catalog.link import link_spec
from eyeq_spi.errors import LocalProtocolError, RemoteProtocolError
from eyeq_spi.link.counters import SpiDiagnosticInfo
from eyeq_spi.link.events import (
    DataReceived,
    DuplicateReceived,
    FrameRejected,
    FramesSkipped,
    LinkEvent,
    ResyncCause,
    Resynchronised,
    SendFailed,
    SendFailReason,
    Sent,
    UnexpectedAck,
)
from eyeq_spi.link.frame import DATA_SIZE, SEQ_MODULO, FrameCodec, FrameKind, NakReason

Role = Literal["host", "eyeq"]
PayloadCheck = Callable[[int, bytes], "NakReason | None"]

_SPEC = link_spec()
_DATA, _ACK, _NAK = int(FrameKind.DATA), int(FrameKind.ACK), int(FrameKind.NAK)
# L10a: after a learning reset, a NUM 0 is taken as the peer's restart within this many windows
# of frames (the peer numbers on until it learns of the reset)
RESTART_HORIZON = 8


@dataclass
class LinkConfig:
    """Every timing and the window size, with the seed's values as defaults (§6 table)."""

    role: Role = "host"
    window: int = _SPEC["window"]["size"]
    resync_after_naks: int = _SPEC["window"]["resync_after_naks"]
    ack_timeout: float = _SPEC["timing"]["ackTimeout"]
    transmit_timeout: float = _SPEC["timing"]["transmitTimeout"]
    frame_gap: float | None = None  # None: frameFlowControl of the role, between DATA frames
    control_gap: float = _SPEC["timing"]["control_gap"]  # between ACK/NAK frames
    codec: FrameCodec = field(default_factory=FrameCodec)
    passive: bool = False  # L9: E is the first DATA frame's NUM, not 0

    def __post_init__(self) -> None:
        if self.role not in ("host", "eyeq"):
            raise LocalProtocolError(f"role must be 'host' or 'eyeq', not {self.role!r}")
        if not 1 <= self.window < SEQ_MODULO // 2:
            raise LocalProtocolError(f"window {self.window} out of range")
        if self.frame_gap is None:
            self.frame_gap = float(_SPEC["timing"]["frameFlowControl"][self.role])
        for name in ("ack_timeout", "transmit_timeout", "frame_gap", "control_gap"):
            if getattr(self, name) < 0:
                raise LocalProtocolError(f"{name} must not be negative")


@dataclass
class _Queued:
    tag: int
    data: bytes
    deadline: float
    waited: bool = False


@dataclass
class _InFlight:
    tag: int
    deadline: float
    sent: float = 0.0


class LinkConnection:
    def __init__(
        self, config: LinkConfig | None = None, *, payload_check: PayloadCheck | None = None
    ) -> None:
        self.config = config or LinkConfig()
        self.codec = self.config.codec
        self.payload_check = payload_check
        self.counters = SpiDiagnosticInfo()
        self.ack_latency: Counter[int] = Counter()  # 10 µs bin -> frames ACKed
        self._events: deque[LinkEvent] = deque()
        self._control: deque[bytes] = deque()
        self._queue: deque[_Queued] = deque()
        self._inflight: OrderedDict[int, _InFlight] = OrderedDict()
        self._tags: dict[int, list[int]] = {}  # tag -> [frames not yet settled, failed flag]
        self.reset()

    # -- state ------------------------------------------------------------------------------
    def reset(self, *, tx_num: int = 0, expected: int = 0, learn: bool = False,
              restart_span: int = 0) -> None:
        """Power-up state: NUM and E back to 0 (L4); queued and in-flight frames are lost.
        ``learn``: E is the next DATA frame's NUM (L10). ``tx_num``/``expected``: other starts,
        for tests of the 4095 -> 0 wrap. ``restart_span``: see :attr:`restart_span`."""
        if not (0 <= tx_num < SEQ_MODULO and 0 <= expected < SEQ_MODULO):
            raise LocalProtocolError("start NUMs must be 0..4095")
        self._tx_num = tx_num
        self._expected = expected
        self._started = not (self.config.passive or learn)  # L9, L10: the receiver learns E
        # L10a: the peer's first frame after its own restart (NUM 0) takes E back to 0
        self._expect_restart_frames = (RESTART_HORIZON * self.config.window if learn
                                       else restart_span)
        self._accepted: OrderedDict[int, bytes] = OrderedDict()  # L6a: last W accepted
        self._last_accepted = 0
        self._restart_tag: int | None = None  # L10: number from 0 once this tag's frames left
        self._expect_restart_until = float("-inf")  # L10: the peer's NUM 0/RSP 0 restarts E
        self._naks_in_row = 0
        self._next_tx = float("-inf")
        self._next_ctl = float("-inf")
        self._control.clear()
        for tag, entry in self._tags.items():
            if not entry[1]:  # frames still queued or in flight are lost with the reset
                self.counters.sendFailedErrorCounter += 1
                self._events.append(SendFailed(tag, None, "reset"))
        self._tags.clear()
        self._queue.clear()
        self._inflight.clear()
        self.counters.busyFrames = 0

    def restart(self) -> None:
        """L10: both directions start afresh, keeping what is queued or in flight: our frames
        are numbered from 0, the next DATA frame received sets E, and none is a duplicate of
        one received before."""
        self._tx_num = 0
        self._started = False
        self._accepted.clear()
        self._last_accepted = 0
        self._naks_in_row = 0
        self._expect_restart_frames = RESTART_HORIZON * self.config.window

    def restart_after(self, tag: int, now: float, expect_for: float = 1.0) -> None:
        """L10 for a message that resets the peer (Switch EyeQ Application): our frames after
        the last of ``tag`` are numbered from 0, and for ``expect_for`` seconds a DATA frame
        with NUM 0 and RSP 0 (the peer's first after its reset) is taken as the new E."""
        self._restart_tag = tag
        self._expect_restart_until = now + expect_for

    @property
    def restart_span(self) -> int:
        """L10a: for how many more DATA frames a NUM 0 outside the window is the peer's restart
        (64 after our own reset, counting down)."""
        return self._expect_restart_frames

    @property
    def expected_num(self) -> int:
        return self._expected

    @property
    def next_num(self) -> int:
        return self._tx_num

    @property
    def in_flight(self) -> int:
        return len(self._inflight)

    @property
    def queued(self) -> int:
        return len(self._queue)

    # -- events -----------------------------------------------------------------------------
    def next_event(self) -> LinkEvent | None:
        return self._events.popleft() if self._events else None

    # -- send path --------------------------------------------------------------------------
    def send(self, data: bytes, tag: int, now: float) -> None:
        """Queue one DATA frame whose data field is ``data`` (zero-padded to 122 bytes)."""
        if len(data) > DATA_SIZE:
            raise LocalProtocolError(f"a frame carries at most {DATA_SIZE} bytes")
        entry = self._tags.setdefault(tag, [0, 0])
        if entry[1]:
            return  # the tag already failed: its later frames are pointless (L7)
        entry[0] += 1
        self._queue.append(_Queued(tag, bytes(data), now + self.config.transmit_timeout))

    def data_to_send(self, now: float) -> list[bytes]:
        """Transfers due at ``now``: ACK/NAK first (``control_gap`` apart), then DATA frames
        (``frame_gap`` apart, at most W in flight)."""
        out: list[bytes] = []
        cfg = self.config
        while self._control and now >= self._next_ctl:
            out.append(self._control.popleft())
            self._next_ctl = now + cfg.control_gap
            if cfg.control_gap > 0:
                break
        gap = float(cfg.frame_gap or 0.0)
        while self._queue and now >= self._next_tx:
            if len(self._inflight) >= cfg.window:
                if not self._queue[0].waited:
                    # A frame is ready but W frames are still in transit (§9.2 fifoNonEmpty).
                    self._queue[0].waited = True
                    self.counters.fifoNonEmptyCounter += 1
                break
            queued = self._queue.popleft()
            num = self._tx_num
            self._tx_num = (num + 1) % SEQ_MODULO
            if queued.tag == self._restart_tag and not any(
                    later.tag == queued.tag for later in self._queue):
                self._tx_num, self._restart_tag = 0, None  # L10: after the reset request
            out.append(self.codec.data_frame(self._last_accepted, num, queued.data))
            self._inflight[num] = _InFlight(queued.tag, now + cfg.ack_timeout, now)
            self.counters.busyFrames = len(self._inflight)
            self._next_tx = now + gap
            if gap > 0:
                break
        return out

    # -- timers -----------------------------------------------------------------------------
    def get_timer(self) -> float | None:
        best: float | None = self._next_ctl if self._control else None
        queue, inflight = self._queue, self._inflight
        if queue:
            due = queue[0].deadline
            if len(inflight) < self.config.window and self._next_tx < due:
                due = self._next_tx
            if best is None or due < best:
                best = due
        if inflight:
            # frames enter in send order: the oldest is due first
            due = next(iter(inflight.values())).deadline
            if best is None or due < best:
                best = due
        return best

    def handle_timer(self, now: float) -> None:
        for num in [n for n, f in self._inflight.items() if f.deadline <= now]:
            inflight = self._inflight.pop(num)
            self._fail(inflight.tag, num, "ack_timeout")
            self._settle(inflight.tag)
        self.counters.busyFrames = len(self._inflight)
        while self._queue and self._queue[0].deadline <= now:
            queued = self._queue.popleft()
            self._fail(queued.tag, None, "transmit_timeout")
            self._settle(queued.tag)

    # -- receive path -----------------------------------------------------------------------
    def receive_data(self, transfer: bytes, now: float) -> None:
        counters = self.counters
        try:
            d, r, rsp, num, crc_ok = self.codec.check(transfer)
        except RemoteProtocolError as exc:  # L8: the header cannot be trusted, so no NAK
            counters.formatErrorCounter += 1
            counters.badLengthTransfers += 1
            self._events.append(FrameRejected(None, None, str(exc)))
            return
        is_control = d in (_ACK, _NAK)
        if not crc_ok:
            counters.dataCRCErrorCounter += 1
            if is_control:
                self._events.append(FrameRejected(None, rsp, "CRC mismatch in ACK/NAK"))
            else:
                self._reject(num, NakReason.CRC_MISMATCH, "CRC mismatch")
            return
        if r != 0 or not (is_control or d == _DATA):
            counters.formatErrorCounter += 1
            detail = f"invalid header D=0x{d:X} R=0x{r:X}"
            if is_control:
                self._events.append(FrameRejected(None, rsp, detail))
            else:
                self._reject(num, NakReason.FORMAT_ERROR, detail)
            return
        if d == _ACK:
            self._on_ack(rsp, now)
        elif d == _NAK:
            self._on_nak(rsp, num)
        else:
            expecting = num == 0 and (
                now <= self._expect_restart_until or self._expect_restart_frames > 0)
            if self._expect_restart_frames > 0:
                self._expect_restart_frames -= 1
            self._on_data(num, transfer[6:], transfer, rsp if expecting else None)

    def _on_data(self, num: int, data: bytes, transfer: bytes,
                 restart_rsp: int | None = None) -> None:
        """``restart_rsp``: the RSP of a NUM 0 frame that may be the peer's first after a reset:
        it is if its RSP is 0 (L10), or if it lies outside the window and is not a copy of the
        NUM 0 accepted since the reset (L10a)."""
        counters, window, modulo = self.counters, self.config.window, SEQ_MODULO
        if not self._started:  # L9: the first DATA frame a passive receiver sees sets E
            self._started = True
            self._expected = num
        ahead = (num - self._expected) % modulo
        behind = (self._expected - num) % modulo
        resync: ResyncCause | None = None
        peer_restart = restart_rsp is not None and (
            restart_rsp == 0 or (ahead >= window and self._accepted.get(num) != transfer))
        if peer_restart:
            self._expect_restart_until = float("-inf")
            self._expect_restart_frames = 0
            if ahead:
                resync = "peer_restart"  # L10: the peer's first frame after its reset
        elif self._naks_in_row >= self.config.resync_after_naks:
            resync = "nak_limit"  # L6: take this frame's NUM as the new E
        elif ahead >= window:
            if 1 <= behind <= window:
                seen = self._accepted.get(num)
                if seen is None:  # L6a: a late frame, skipped over earlier
                    counters.sequenceErrorCounter += 1
                    counters.lateFrames += 1
                    self._reject(num, NakReason.OUT_OF_WINDOW,
                                 f"late frame NUM {num}: skipped at E={self._expected}")
                    return
                if seen == transfer:  # L6a: a true duplicate
                    counters.duplicateFrames += 1
                    self._naks_in_row = 0
                    self._control.append(self.codec.ack(num))
                    self._events.append(DuplicateReceived(num))
                    return
                resync = "peer_reset"  # L6a: same NUM, other bytes: the peer started over
            else:
                counters.sequenceErrorCounter += 1
                self._naks_in_row += 1
                detail = f"NUM {num} outside window at E={self._expected}"
                self._reject(num, NakReason.OUT_OF_WINDOW, detail)
                return
        if resync is not None:
            # the transport aborts its open transfer on this event before it sees the frame
            counters.resynchronisations += 1
            self._accepted.clear()
            self._expected = num
            ahead = 0
            self._events.append(Resynchronised(num, resync))
        if self.payload_check is not None:
            reason = self.payload_check(num, data)
            if reason is not None:
                if reason is NakReason.FORMAT_ERROR:
                    counters.formatErrorCounter += 1
                self._reject(num, reason, "payload header rejected by the transport")
                return
        if ahead:
            counters.skippedFrames += ahead
            self._events.append(FramesSkipped(self._expected, num, ahead))
        self._accepted_frame(num, transfer)
        self._control.append(self.codec.ack(num))
        self._events.append(DataReceived(num, data))

    def _on_ack(self, rsp: int, now: float) -> None:
        inflight = self._inflight.pop(rsp, None)
        if inflight is None:
            self.counters.unexpectedAckCounter += 1
            self._events.append(UnexpectedAck("ACK", rsp))
            return
        # send -> ACK latency in 10 µs bins
        self.ack_latency[int((now - inflight.sent) * 1e5)] += 1
        self.counters.busyFrames = len(self._inflight)
        self.counters.framesAcked += 1
        self._settle(inflight.tag)

    def _on_nak(self, rsp: int, reason_code: int) -> None:
        try:
            reason: NakReason | None = NakReason(reason_code)
        except ValueError:
            reason = None
        self.counters.naksReceived[reason_code] = self.counters.naksReceived.get(reason_code, 0) + 1
        inflight = self._inflight.pop(rsp, None)
        if inflight is None:
            self.counters.unexpectedAckCounter += 1
            self._events.append(UnexpectedAck("NAK", rsp))
            return
        self.counters.busyFrames = len(self._inflight)
        self._fail(inflight.tag, rsp, "nak", reason)
        self._settle(inflight.tag)

    def _reject(self, num: int, reason: NakReason, detail: str) -> None:
        self.counters.naksSent[int(reason)] = self.counters.naksSent.get(int(reason), 0) + 1
        self._control.append(self.codec.nak(num, reason))
        self._events.append(FrameRejected(reason, num, detail))

    # -- tag bookkeeping --------------------------------------------------------------------
    def _fail(self, tag: int, num: int | None, why: SendFailReason,
              nak: NakReason | None = None) -> None:
        if tag == self._restart_tag:
            self._restart_tag = None  # the reset request never left whole: no restart
        entry = self._tags.get(tag)
        if entry is None or entry[1]:
            return
        entry[1] = 1
        self.counters.sendFailedErrorCounter += 1
        self._events.append(SendFailed(tag, num, why, nak))
        kept: deque[_Queued] = deque()
        for queued in self._queue:
            if queued.tag == tag:
                entry[0] -= 1
            else:
                kept.append(queued)
        self._queue = kept
        if entry[0] <= 0:
            del self._tags[tag]

    def _settle(self, tag: int) -> None:
        entry = self._tags.get(tag)
        if entry is None:
            return
        entry[0] -= 1
        if entry[0] <= 0:
            del self._tags[tag]
            if not entry[1]:
                self._events.append(Sent(tag))

    def _accepted_frame(self, num: int, transfer: bytes) -> None:
        """A DATA frame accepted (L6): E moves past it, and it joins the last W accepted
        frames L6a tells duplicates from peer resets by."""
        modulo = SEQ_MODULO
        self._naks_in_row = 0
        self._expected = (num + 1) % modulo
        self._last_accepted = num
        acc = self._accepted
        acc.pop(num, None)
        acc[num] = bytes(transfer)
        while acc and (self._expected - next(iter(acc))) % modulo > self.config.window:
            acc.popitem(last=False)  # only [E-W, E) can be a duplicate
        self.counters.framesReceived += 1
