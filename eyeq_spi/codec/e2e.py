"""End-to-end protection of safety structs (decision D5): ``crc_16`` over the listed signals and
a rolling frame counter stepping +1 mod 256 per structure instance."""

from __future__ import annotations

import binascii
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.codec.layout import CrcPlan, Layout

Protector = Callable[[bytearray, "E2EState | None"], None]


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


def plan_crc(buf: bytes | bytearray, plan: CrcPlan, base: int = 0) -> int:
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


def _batches(plans: list[CrcPlan]) -> list[list[int]]:
    """Runs of consecutive CRCs of one shape (range sizes, counter size: the elements of an
    array) none of which covers another's CRC or counter: their counters can all be stepped
    first, in order, and their covered bytes gathered at once (same values as one by one)."""
    out: list[list[int]] = []
    for index, plan in enumerate(plans):
        shape = (tuple(s for _, s in plan.ranges), plan.counter_size, plan.counter_offset is None)
        prev = out[-1] if out else None
        if prev is not None and shape == _shape_of(plans[prev[0]]) and all(
                _apart(plans[j], plan) and _apart(plan, plans[j]) for j in prev):
            prev.append(index)
        else:
            out.append([index])
    return out


def _shape_of(plan: CrcPlan) -> tuple[Any, ...]:
    return (tuple(s for _, s in plan.ranges), plan.counter_size, plan.counter_offset is None)


def _apart(plan: CrcPlan, other: CrcPlan) -> bool:
    """``a`` covers neither ``b``'s CRC nor its counter."""
    fields = [(other.crc_offset, 2)]
    if other.counter_offset is not None:
        fields.append((other.counter_offset, other.counter_size))
    return not any(o < fo + fs and fo < o + s for o, s in plan.ranges for fo, fs in fields)


def compile_protector(layout: Layout) -> Protector:
    """``e2e.protect(buf, layout, state)`` as generated code (D5): per CRC of
    ``layout.crc_plan``, inner first, the rolling counter then ``crc_hqx`` seeded 0xFFFF chained
    over the covered ranges, every offset a literal. A run of same-shaped CRCs (one per element
    of an array, :func:`_batches`) gathers its covered bytes with one numpy index instead."""
    env: dict[str, Any] = {"h": binascii.crc_hqx}
    lines = ["def _protect(b, state):"]
    plans = layout.crc_plan
    for batch in _batches(plans):
        for index in batch:
            plan = plans[index]
            if plan.counter_offset is not None:
                env[f"K{index}"] = counter_key(layout, plan)
                counter_at, counter_size = plan.counter_offset, plan.counter_size
                lines += ["    if state is not None:",
                          f"        b[{counter_at}:{counter_at + counter_size}] = "
                          f"state.next_counter(K{index}, {counter_size})"
                          f".to_bytes({counter_size}, 'little')"]
            if len(batch) > 1:
                continue
            expr = "65535"
            for offset, size in plan.ranges:
                expr = f"h(b[{offset}:{offset + size}], {expr})"
            crc_at = plan.crc_offset
            lines.append(f"    b[{crc_at}:{crc_at + 2}] = ({expr}).to_bytes(2, 'little')")
        if len(batch) > 1:
            import numpy as np  # only for arrays of protected structs (DASP generation)

            env["np"] = np
            index = batch[0]
            env[f"G{index}"] = np.array([[o + k for o, s in plans[j].ranges for k in range(s)]
                                         for j in batch], dtype=np.intp)
            env[f"O{index}"] = [plans[j].crc_offset for j in batch]
            lines += [f"    g = np.frombuffer(b, dtype=np.uint8)[G{index}]",
                      f"    for r, o in zip(g, O{index}):",
                      "        b[o:o + 2] = h(r, 65535).to_bytes(2, 'little')"]
    lines.append("    return None")
    exec("\n".join(lines), env)
    fn: Protector = env["_protect"]
    return fn


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
