"""The fault-injecting link shim between our tester node and the wire: it records both channels
in the trace, and can withhold our ACKs, drop or duplicate chosen DATA frames, and inject
crafted frames. It never changes what our own stack believes: a dropped frame is simply never
ACKed, so our link fails it after ackTimeout (L7)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from eyeq_spi.conformance.trace import Trace
from eyeq_spi.link.frame import DATA_SIZE, Frame, FrameCodec, FrameKind
from eyeq_spi.runner.node import Node


@dataclass
class _Rule:
    payload: bytes  # the data field (122 bytes) that identifies the frame
    label: str
    action: str  # "label" | "drop" | "duplicate"


class Shim:
    """A :class:`Node` that wraps the tester node and records both channels in ``trace``."""

    def __init__(self, node: Node, trace: Trace) -> None:
        self.node = node
        self.trace = trace
        self.frames = FrameCodec()
        self.hold_acks_until = float("-inf")
        self._inject: deque[tuple[bytes, str]] = deque()
        self._rules: list[_Rule] = []

    def watch(self, payload: bytes, label: str, action: str = "label") -> None:
        """Label (or drop, or duplicate) the next DATA frame whose data field is ``payload``."""
        self._rules.append(_Rule(payload.ljust(DATA_SIZE, b"\0"), label, action))

    def probe(self, label: str, *, num: int, d: int = FrameKind.DATA, r: int = 0,
              bad_crc: bool = False) -> None:
        """Inject one crafted DATA-like frame with ``num`` (an invalid D gets the CRC of a DATA
        frame, specs/link.yaml crc.coverage.other)."""
        frame = Frame(d, r, 0, num % 4096, b"\x00\x01\xff".ljust(DATA_SIZE, b"\0"))
        raw = bytearray(self.frames.encode(frame))
        if bad_crc:
            raw[4] ^= 0x5A
        self._inject.append((bytes(raw), label))

    def receive_data(self, transfer: bytes, now: float) -> None:
        self.trace.add(self.trace.dut_dir, now, transfer)
        self.node.receive_data(transfer, now)

    def data_to_send(self, now: float) -> list[bytes]:
        out: list[bytes] = []
        while self._inject:
            raw, injected = self._inject.popleft()
            self.trace.add(self.trace.our_dir, now, raw, injected)
            out.append(raw)
        for transfer in self.node.data_to_send(now):
            kind = self.frames.unpack_header(int.from_bytes(transfer[:4], "little"))[0]
            if kind in (FrameKind.ACK, FrameKind.NAK) and now < self.hold_acks_until:
                continue
            rule = next((rule for rule in self._rules if rule.payload == transfer[6:]), None) \
                if kind == FrameKind.DATA else None
            if rule is not None:
                self._rules.remove(rule)
                if rule.action == "drop":
                    self.trace.mark(now, "dropped", probe=rule.label)
                    continue
                if rule.action == "duplicate":
                    self.trace.add(self.trace.our_dir, now, transfer)  # the original
                    out.append(transfer)
            self.trace.add(self.trace.our_dir, now, transfer, None if rule is None else rule.label)
            out.append(transfer)
        return out

    def get_timer(self) -> float | None:
        return self.node.get_timer()

    def handle_timer(self, now: float) -> None:
        self.node.handle_timer(now)
