"""The conformance trace: every transfer on both SPI channels, in order, with its time, decoded
as frames; the messages a passive receiver reassembles from each channel; and the marks the
script leaves (probes sent, faults injected, resets). Judges read only this (and, for
``--builtin``, the public state of our own implementations).

Each channel's passive receiver is a :class:`TransportConnection` in the role of the side that
receives it, restarted where the side we play restarts its own (docs/conformance.md, L6-L10a).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.codec.message import DecodedMessage, MessageCodec
from eyeq_spi.link.connection import LinkConfig, Role
from eyeq_spi.link.events import Resynchronised
from eyeq_spi.link.frame import FRAME_SIZE, FrameCodec, FrameKind
from eyeq_spi.transport.connection import TransportConnection
from eyeq_spi.transport.events import MessageReceived

H2E, E2H = "h2e", "e2h"
RECEIVER: dict[str, Role] = {H2E: "eyeq", E2H: "host"}
_KIND_NAMES = {int(kind): kind.name for kind in FrameKind}


@dataclass(frozen=True, slots=True)
class Xfer:
    """One transfer on the wire. ``kind`` is DATA/ACK/NAK/BAD (invalid D or R)/LEN (not 128)."""

    index: int
    time: float
    direction: str
    data: bytes
    kind: str
    rsp: int
    num: int
    crc_ok: bool
    probe: str | None = None  # the label of a frame we crafted or altered on purpose

    @property
    def ttype(self) -> int:
        return self.data[6] if len(self.data) > 7 else -1


@dataclass
class Msg:
    """A message the passive receiver reassembled. ``indices`` are its frames' trace indices."""

    direction: str
    data: bytes
    indices: list[int]
    t_first: float
    time: float
    decoded: DecodedMessage

    @property
    def name(self) -> str:
        return self.decoded.name or self.decoded.protocol

    @property
    def header(self) -> dict[str, Any]:
        return self.decoded.header

    @property
    def fields(self) -> dict[str, Any]:
        return self.decoded.fields


@dataclass(frozen=True, slots=True)
class Mark:
    time: float
    label: str
    info: dict[str, Any] = field(default_factory=dict)


@dataclass
class _Passive:
    conn: TransportConnection
    index_of_num: dict[int, tuple[int, float]] = field(default_factory=dict)


class Trace:
    def __init__(self, dut: str, sw: str | None = None, *, realtime: bool = False) -> None:
        self.dut = dut
        self.dut_dir = E2H if dut == "eyeq" else H2E
        self.our_dir = H2E if dut == "eyeq" else E2H
        self.codec = MessageCodec(sw)
        self.frames = FrameCodec()
        self.realtime = realtime
        self.xfers: list[Xfer] = []
        self._msgs: list[Msg] = []
        # reassembly and decoding wait until someone asks; a str marks a restart of that side
        self._unfed: list[Xfer | str] = []
        self.marks: list[Mark] = []
        self.faults: list[tuple[float, float, str]] = []  # windows where we disturb the link
        self.stalls: list[tuple[float, float]] = []  # real time: our own loop came late (load.py)
        self.end = 0.0
        # (time, direction) of each restart the frames showed (L4, L6, L6a, L10a)
        self._restarts: list[tuple[float, str]] = []
        self._passive = {direction: _Passive(TransportConnection(LinkConfig(role=role)))
                         for direction, role in RECEIVER.items()}

    # -- recording -------------------------------------------------------------------------
    def mark(self, time: float, label: str, **info: Any) -> None:
        self.marks.append(Mark(time, label, info))

    def fault(self, start: float, end: float, label: str) -> None:
        self.faults.append((start, end, label))

    def restart_passive(self, direction: str) -> None:
        """The receiver of ``direction`` restarted (L10, L10a), once the frames recorded so far
        are fed (decoding them now would stall a real-time loop)."""
        self._unfed.append(direction)

    @property
    def msgs(self) -> list[Msg]:
        """Every reassembled message so far (decoded only when asked for)."""
        self._catch_up()
        return self._msgs

    def _catch_up(self) -> None:
        unfed, self._unfed = self._unfed, []
        for xfer in unfed:
            if isinstance(xfer, str):
                self._passive[xfer].conn.restart()
            else:
                self._feed(xfer)

    def add(self, direction: str, time: float, data: bytes, probe: str | None = None) -> Xfer:
        idx = len(self.xfers)
        self.end = max(self.end, time)
        kind, rsp, num, crc_ok = "LEN", -1, -1, False
        if len(data) == FRAME_SIZE:
            d, r, rsp, num, crc_ok = self.frames.check(data)
            kind = _KIND_NAMES.get(d, "BAD") if r == 0 else "BAD"
        xfer = Xfer(idx, time, direction, bytes(data), kind, rsp, num, crc_ok, probe)
        self.xfers.append(xfer)
        if kind in ("DATA", "BAD") and crc_ok:
            self._unfed.append(xfer)
        return xfer

    def _feed(self, xfer: Xfer) -> None:
        passive = self._passive[xfer.direction]
        conn = passive.conn
        if xfer.kind == "DATA" and xfer.num == 0 and xfer.rsp == 0 and conn.link.expected_num != 0:
            # L4: NUM 0 and RSP 0 again: that side's driver restarted; L10: both directions
            # start afresh
            for direction in (H2E, E2H):
                self._passive[direction].conn.restart()
            self._restarts.append((xfer.time - 1e-9, xfer.direction))
        timer = conn.get_timer()
        if timer is not None and timer <= xfer.time:
            conn.handle_timer(xfer.time)
        if xfer.kind == "DATA":
            passive.index_of_num[xfer.num] = (xfer.index, xfer.time)
        conn.receive_data(xfer.data, xfer.time)
        conn.data_to_send(float("inf"))
        while (ev := conn.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                where = [passive.index_of_num.get(n, (xfer.index, xfer.time)) for n in ev.frames]
                decoded = self.codec.decode(ev.data)
                self._msgs.append(Msg(xfer.direction, ev.data, [i for i, _ in where],
                                     where[0][1], xfer.time, decoded))
            elif isinstance(ev, Resynchronised):  # L6, L6a, L10a: the sender started over
                self._restarts.append((xfer.time - 1e-9, xfer.direction))

    # -- queries ---------------------------------------------------------------------------
    def dut_msgs(self, name: str | None = None) -> list[Msg]:
        return [m for m in self.msgs if m.direction == self.dut_dir
                and (name is None or m.name == name)]

    def our_msgs(self, name: str | None = None) -> list[Msg]:
        return [m for m in self.msgs if m.direction == self.our_dir
                and (name is None or m.name == name)]

    def replies(self, tag: int, function: int, since: float) -> list[Msg]:
        """The DUT's MESP replies to ``function`` with tag counter ``tag`` within 1 s of
        ``since``: the answers to one of our probes."""
        return [m for m in self.dut_msgs() if m.decoded.protocol == "MESP"
                and m.header.get("reply") and m.header.get("counter") == tag
                and m.header.get("function") == function and since <= m.time <= since + 1.0]

    def marks_of(self, label: str) -> list[Mark]:
        return [m for m in self.marks if m.label == label]

    def first_mark(self, label: str) -> Mark | None:
        return next((mark for mark in self.marks if mark.label == label), None)

    def disturbed(self, t0: float, t1: float, settle: float = 0.15) -> bool:
        """True if [t0, t1] touches a fault window (plus ``settle`` seconds after it)."""
        return any(t0 <= end + settle and t1 >= start for start, end, _ in self.faults)

    def restarts(self, direction: str | None = None) -> list[float]:
        """When a receiver restarted on what the frames showed (a NUM 0 and RSP 0, a
        resynchronisation): the sender of ``direction`` (of either, if None) started over."""
        self._catch_up()
        return [t for t, d in self._restarts if direction is None or d == direction]

    def stalled(self, t0: float, t1: float) -> bool:
        """True if a stall of our own loop (real time, load.py) overlaps [t0, t1]: our ACKs
        may have come after the peer's ackTimeout there, and a message of the peer be lost."""
        return any(a <= t1 and b >= t0 for a, b in self.stalls)

    def resets(self) -> list[float]:
        """Every reset: those the script marked (ours, the reset line, soft resets) and every
        restart a receiver saw."""
        return [m.time for m in self.marks
                if m.label in ("our_reset", "reset_line", "soft_reset", "dut_reset")] \
            + self.restarts()
