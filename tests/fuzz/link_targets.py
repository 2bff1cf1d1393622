"""Link and transport receive path.

``link_rx``: arbitrary transfers (raw bytes, or frames with a valid CRC and fuzzed header and
transport fields) into a receiving :class:`TransportConnection`. Oracle: a frame is accepted
(``framesReceived`` steps) only if L1/L8 (128 bytes), L3 (CRC-16/CCITT-FALSE, checked here
independently with ``binascii.crc_hqx``), L2 (D = DATA, R = 0) and L5's header checks (transport
type, single size 1..120, first ``total`` 117..limit) allow it; every delivered message is
1..limit bytes.

``transport_pair``: a sender and a receiver; the input sends distinct messages, damages DATA
frames on the way (drop, duplicate, hold behind the next, flip a bit, truncate), resets the
sender (a fast peer reset, NUM and transfer ID back to 0) and moves time. Oracles: every
delivered message equals one that was sent, and never more often than it was sent (no splice
across a reset, L6a); without resets, every message the sender saw ACKed was delivered (L6a: a
late frame is NAKed, not ACKed as a duplicate).
"""

from __future__ import annotations

import binascii
from collections import Counter

from eyeq_spi.link.connection import LinkConfig
from eyeq_spi.link.frame import FRAME_SIZE, SEQ_MODULO, FrameCodec
from eyeq_spi.transport.connection import TransportConnection
from eyeq_spi.transport.events import MessageReceived, MessageSent

from .core import FIGURES, Finding, Reader

CODEC = FrameCodec()
LIMITS = {"host": 8191, "eyeq": 512}


def _crc_ok(t: bytes) -> bool:
    return binascii.crc_hqx(t[:4] + t[6:], 0xFFFF) == int.from_bytes(t[4:6], "little")


def _allowed(t: bytes, limit: int) -> str | None:
    """Why the rules forbid accepting ``t`` as a DATA frame, or None."""
    if len(t) != FRAME_SIZE:
        return f"L8: {len(t)} bytes"
    if not _crc_ok(t):
        return "L3: CRC mismatch"
    if t[0] & 0xF != 0x8 or t[0] >> 4 != 0:
        return f"L2: D/R = 0x{t[0]:02X}"
    kind, size = t[6], t[7]
    if kind == 0 and not 1 <= size <= 120:
        return f"T2: single size {size}"
    if kind == 1 and not 117 <= int.from_bytes(t[8:12], "little") <= limit:
        return "T3/T6: first-frame total"
    if kind > 2:
        return f"T1: transport type {kind}"
    return None


def _crafted(r: Reader, expected: int) -> bytes:
    """A frame with a valid CRC whose header and transport fields come from the input."""
    d = (0x8, 0x8, 0x8, 0x4, 0x2, r.u8() & 0xF)[r.u8() % 6]
    rr = 0 if r.u8() % 8 else r.u8() & 0xF
    num = (expected + r.u8() % 24 - 12) % SEQ_MODULO if r.u8() % 4 else r.u16() % SEQ_MODULO
    rsp = r.u16() % SEQ_MODULO
    kind = r.u8() % 5
    body = bytearray(r.take(r.u8() % 123).ljust(122, b"\0"))
    if kind < 3:
        body[0] = kind
    if kind == 1 and r.u8() & 1:
        body[2:6] = (116 + r.u16() % 600).to_bytes(4, "little")
    word = CODEC.pack_header(d, rr, rsp, num).to_bytes(4, "little")
    crc = binascii.crc_hqx(word + bytes(body), 0xFFFF) if d not in (0x4, 0x2) \
        else binascii.crc_hqx(word, 0xFFFF)
    return word + crc.to_bytes(2, "little") + bytes(body)


def link_rx(data: bytes) -> None:
    r = Reader(data)
    role = "host" if r.u8() & 1 else "eyeq"
    limit = LIMITS[role]
    conn = TransportConnection(LinkConfig(role=role))  # type: ignore[arg-type]
    conn.reset(expected=r.u16() % SEQ_MODULO)
    now = 0.0
    while not r.done:
        op = r.u8()
        now += (op >> 5) * 0.004
        t = r.take(r.u8()) if op & 1 else _crafted(r, conn.link.expected_num)
        if not t:
            continue
        before = conn.link.counters.framesReceived
        conn.receive_data(t, now)
        FIGURES["frames"] += 1
        if conn.link.counters.framesReceived != before:
            why = _allowed(t, limit)
            if why is not None:
                raise Finding(f"accepted a frame the rules forbid ({why}): {t.hex()}")
        timer = conn.get_timer()
        if timer is not None and timer <= now:
            conn.handle_timer(now)
        conn.data_to_send(now)
        while (ev := conn.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                FIGURES["messages"] += 1
                if not 1 <= len(ev.data) <= limit:
                    raise Finding(f"delivered a message of {len(ev.data)} bytes")


class _Pair:
    def __init__(self, r: Reader) -> None:
        self.r = r
        self.tx = TransportConnection(LinkConfig(role="eyeq"))
        self.rx = TransportConnection(LinkConfig(role="host"))
        # 4094: NUM wraps to 0 inside the first multi-frame message
        start = 4094 if r.u8() & 1 else r.u16() % SEQ_MODULO
        self.tx.reset(tx_num=start, transfer_id=r.u8())
        self.rx.reset(expected=start)
        self.now = 0.0
        self.fault = 0
        self.held: bytes | None = None
        self.sent: Counter[bytes] = Counter()
        self.delivered: Counter[bytes] = Counter()
        self.by_id: dict[int, bytes] = {}
        self.acked: list[bytes] = []
        self.resets = 0

    def wire(self, t: bytes) -> list[bytes]:
        fault, self.fault = self.fault, 0
        out: list[bytes]
        if self.held is not None:
            out, self.held = [t, self.held], None
            return out
        if fault == 1:
            return []
        if fault == 2:
            return [t, t]
        if fault == 3:
            self.held = t
            return []
        if fault == 4:
            b = bytearray(t)
            bit = self.r.u16() % (FRAME_SIZE * 8)
            b[bit // 8] ^= 1 << (bit % 8)
            return [bytes(b)]
        if fault == 5:
            return [t[: self.r.u8() % FRAME_SIZE]] if self.r.u8() % FRAME_SIZE else []
        return [t]

    def pump(self, until: float) -> None:
        for _ in range(100_000):
            moved = False
            for t in self.tx.data_to_send(self.now):
                moved = True
                FIGURES["frames"] += 1
                for x in self.wire(t):
                    if x:
                        self.rx.receive_data(x, self.now)
            for t in self.rx.data_to_send(self.now):
                moved = True
                self.tx.receive_data(t, self.now)
            self.drain()
            if moved:
                continue
            timers = [tm for c in (self.tx, self.rx) if (tm := c.get_timer()) is not None]
            due = [tm for tm in timers if tm <= until]
            if not due:
                self.now = max(self.now, until)
                return
            self.now = max(self.now, min(due))
            for c in (self.tx, self.rx):
                tm = c.get_timer()
                if tm is not None and tm <= self.now:
                    c.handle_timer(self.now)
        raise Finding("the pair never went quiet")

    def drain(self) -> None:
        while (ev := self.rx.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                FIGURES["messages"] += 1
                self.delivered[ev.data] += 1
                if self.delivered[ev.data] > self.sent[ev.data]:
                    what = "never sent" if not self.sent[ev.data] else "delivered too often"
                    raise Finding(f"message {what} (spliced?): {len(ev.data)} bytes, frames "
                                  f"{ev.frames}, {self.resets} resets")
        while (ev := self.tx.next_event()) is not None:
            if isinstance(ev, MessageSent):
                self.acked.append(self.by_id[ev.message_id])


def transport_pair(data: bytes) -> None:
    """A frame held for reordering still arrives when the peer resets, before the reset's
    frames: frames are reordered among themselves, never across a reset, because SPI and byte
    streams keep order (T6a; ``tests/test_transport_connection.py`` pins what a channel that
    reorders across a reset would do)."""
    _transport_pair(data, lose_held_at_reset=False)


def transport_pair_wire(data: bytes) -> None:
    """The same, but a peer reset loses a frame still held on the wire, as on a real bus."""
    _transport_pair(data, lose_held_at_reset=True)


def _transport_pair(data: bytes, *, lose_held_at_reset: bool) -> None:
    r = Reader(data)
    allow_reset = bool(r.u8() & 1)
    p = _Pair(r)
    k = 0
    while not r.done:
        op = r.u8() % 8
        if op <= 2:
            k += 1
            size = 1 + (r.u16() % (600 if op else 120))
            stamp = k.to_bytes(4, "little") + r.take(4).ljust(4, b"\0")
            msg = (stamp * (size // 8 + 1))[:size]
            p.sent[msg] += 1
            p.by_id[p.tx.send(msg, p.now)] = msg
        elif op == 3 and allow_reset:
            p.resets += 1
            if p.held is not None and not lose_held_at_reset:
                p.rx.receive_data(p.held, p.now)  # in flight before the reset: it arrives first
            p.held = None
            p.tx.reset()  # the peer starts over: NUM 0, transfer ID 0 (L4)
            p.now += 0.026  # no reset is faster than the 25 ms reassembly timeout (T6a)
        elif op == 4:
            p.fault = 1 + r.u8() % 5
        else:
            p.pump(p.now + (r.u8() % 32) * 0.0005)
    p.pump(p.now + 0.2)
    if p.held is not None:  # release a frame still held for reordering
        p.rx.receive_data(p.held, p.now)
        p.held = None
        p.pump(p.now + 0.2)
    if not p.resets:
        lost = [m for m in p.acked if not p.delivered[m]]
        if lost:
            raise Finding(f"{len(lost)} messages ACKed to the sender were never delivered")
