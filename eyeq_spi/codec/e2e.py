"""End-to-end protection of safety structs (decision D5): ``crc_16`` over the listed signals and
a rolling frame counter stepping +1 mod 256 per structure instance."""

from __future__ import annotations

import binascii
from dataclasses import dataclass, field

from eyeq_spi.codec.layout import CrcPlan, Layout


@dataclass
class E2EState:
    """Rolling counters per protected structure, keyed by (message, path): one per stream."""

    sent: dict[tuple[str, str], int] = field(default_factory=dict)
    seen: dict[tuple[str, str], int] = field(default_factory=dict)
    crc_errors: int = 0
    counter_errors: int = 0

    def next_counter(self, key: tuple[str, str], size: int) -> int:
        modulo = 1 << (8 * size)
        value = (self.sent.get(key, -1) + 1) % modulo
        self.sent[key] = value
        return value


def counter_key(layout: Layout, plan: CrcPlan) -> tuple[str, str]:
    # one rolling counter per CRC: eyeq_road_info_t (SW8.1+) has two CRCs, each with its own
    # counter, at the same path (found by the conformance suite: both stepped +2)
    return (layout.name, f"{plan.path}#{plan.field}")


def crc_label(layout: Layout, plan: CrcPlan) -> str:
    return f"{layout.name}.{plan.path}" if plan.path else layout.name


def plan_crc(buf: bytes | bytearray | memoryview, plan: CrcPlan, base: int = 0) -> int:
    """The CRC of ``plan`` over ``buf`` (the struct at ``base``): ``crc16`` is ``crc_hqx``
    seeded 0xFFFF (D5), chained over the covered ranges, so no bytes are joined."""
    crc = 0xFFFF
    for offset, size in plan.ranges:
        crc = binascii.crc_hqx(buf[base + offset : base + offset + size], crc)
    return crc


def protect(buf: bytearray, layout: Layout, state: E2EState | None, base: int = 0) -> None:
    """Fill every rolling counter (when ``state`` is given) and every CRC, inner first."""
    for plan in layout.crc_plan:
        if state is not None and plan.counter_offset is not None:
            value = state.next_counter(counter_key(layout, plan), plan.counter_size)
            counter_at = base + plan.counter_offset
            size = plan.counter_size
            buf[counter_at : counter_at + size] = value.to_bytes(size, "little")
        crc_at = base + plan.crc_offset
        buf[crc_at : crc_at + 2] = plan_crc(buf, plan, base).to_bytes(2, "little")


def verify(data: bytes, layout: Layout, state: E2EState | None) -> list[str]:
    """Check every CRC and, with ``state``, every counter step. Returns the problems found (a
    mismatch rejects that structure; it is counted, never raised)."""
    errors: list[str] = []
    for plan in layout.crc_plan:
        crc_at = plan.crc_offset
        got = int.from_bytes(data[crc_at : crc_at + 2], "little")
        want = plan_crc(data, plan)
        if got != want:
            errors.append(f"E2E CRC mismatch in {crc_label(layout, plan)}: "
                          f"{plan.field}=0x{got:04X}, computed 0x{want:04X}")
            if state is not None:
                state.crc_errors += 1
        if state is not None and plan.counter_offset is not None:
            counter_at = plan.counter_offset
            value = int.from_bytes(data[counter_at : counter_at + plan.counter_size], "little")
            key = counter_key(layout, plan)
            last = state.seen.get(key)
            modulo = 1 << (8 * plan.counter_size)
            if last is not None and value != (last + 1) % modulo:
                errors.append(f"E2E counter jump in {crc_label(layout, plan)}: "
                              f"expected {(last + 1) % modulo}, got {value}")
                state.counter_errors += 1
            state.seen[key] = value
    return errors
