"""End-to-end protection of safety structs (decision D5): ``crc_16`` over the listed signals and
a rolling frame counter stepping +1 mod 256 per structure instance."""

from __future__ import annotations

from dataclasses import dataclass, field

from eyeq_spi.codec.layout import CrcPlan, Layout, compute_crc


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


def _key(layout: Layout, plan: CrcPlan) -> tuple[str, str]:
    # one rolling counter per CRC: eyeq_road_info_t (SW8.1+) has two CRCs, each with its own
    # counter, at the same path (found by the conformance suite: both stepped +2)
    return (layout.name, f"{plan.path}#{plan.field}")


def _label(layout: Layout, plan: CrcPlan) -> str:
    return f"{layout.name}.{plan.path}" if plan.path else layout.name


def protect(buf: bytearray, layout: Layout, state: E2EState | None, base: int = 0) -> None:
    """Fill every rolling counter (when ``state`` is given) and every CRC, inner first."""
    for plan in layout.crc_plan:
        if state is not None and plan.counter_offset is not None:
            value = state.next_counter(_key(layout, plan), plan.counter_size)
            o = base + plan.counter_offset
            buf[o : o + plan.counter_size] = value.to_bytes(plan.counter_size, "little")
        shifted = plan if base == 0 else CrcPlan(
            plan.path, plan.field, plan.crc_offset + base,
            plan.counter_offset, plan.counter_size,
            tuple((o + base, s) for o, s in plan.ranges),
        )
        crc = compute_crc(buf, shifted)
        buf[base + plan.crc_offset : base + plan.crc_offset + 2] = crc.to_bytes(2, "little")


def verify(data: bytes, layout: Layout, state: E2EState | None) -> list[str]:
    """Check every CRC and, with ``state``, every counter step. Returns the problems found (a
    mismatch rejects that structure; it is counted, never raised)."""
    errors: list[str] = []
    for plan in layout.crc_plan:
        o = plan.crc_offset
        got = int.from_bytes(data[o : o + 2], "little")
        want = compute_crc(data, plan)
        if got != want:
            errors.append(f"E2E CRC mismatch in {_label(layout, plan)}: "
                          f"{plan.field}=0x{got:04X}, computed 0x{want:04X}")
            if state is not None:
                state.crc_errors += 1
        if state is not None and plan.counter_offset is not None:
            c = plan.counter_offset
            value = int.from_bytes(data[c : c + plan.counter_size], "little")
            key = _key(layout, plan)
            last = state.seen.get(key)
            modulo = 1 << (8 * plan.counter_size)
            if last is not None and value != (last + 1) % modulo:
                errors.append(f"E2E counter jump in {_label(layout, plan)}: "
                              f"expected {(last + 1) % modulo}, got {value}")
                state.counter_errors += 1
            state.seen[key] = value
    return errors
