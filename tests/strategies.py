"""Hypothesis strategies derived from specs/: ranges, enums and array sizes of each member."""

from __future__ import annotations

import math
import struct
from typing import Any

from hypothesis import strategies as st

from eyeq_spi.catalog.messages import Catalog, InitSignal, Member
from eyeq_spi.codec.layout import INT_RANGE, Layout


def _f32(x: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", x))[0])


def member_value(cat: Catalog, m: Member, typ: str) -> st.SearchStrategy[Any]:
    if typ in ("real32", "real64"):
        lo = m.min if m.min is not None and math.isfinite(m.min) else -1e6
        hi = m.max if m.max is not None and math.isfinite(m.max) else 1e6
        if lo > hi:
            lo, hi = hi, lo
        # drawn as float64 and rounded to binary32 (the wire type) where needed
        return st.floats(lo, hi, allow_nan=False, allow_infinity=False).map(
            _f32 if typ == "real32" else float
        )
    tlo, thi = INT_RANGE[typ]
    if m.enum and m.enum in cat.enums:
        values = [v for v in cat.enums[m.enum].values if tlo <= v <= thi]
        if cat.enums[m.enum].kind != "flags" and values:
            return st.sampled_from(sorted(values))
    if m.values:
        values = [v for v in m.values if tlo <= v <= thi]
        if values:
            return st.sampled_from(sorted(values))
    lo, hi = tlo, thi
    if m.min is not None and m.max is not None and tlo <= m.min <= m.max <= thi:
        lo, hi = math.ceil(m.min), math.floor(m.max)
        if lo > hi:
            lo, hi = tlo, thi
    return st.integers(lo, hi)


def layout_values(cat: Catalog, lay: Layout) -> st.SearchStrategy[dict[str, Any]]:
    parts: dict[str, st.SearchStrategy[Any]] = {}
    for f in lay.fields:
        m = f.member
        if f.bits is not None:
            parts[f.name] = st.integers(0, (1 << (f.bits[1] - f.bits[0] + 1)) - 1)
            continue
        child = lay.children.get(f.name)
        one = layout_values(cat, child) if child else member_value(cat, m, f.type)
        parts[f.name] = st.lists(one, min_size=f.count, max_size=f.count) if f.count else one
    return st.fixed_dictionaries(parts)


def signal_value(sig: InitSignal) -> st.SearchStrategy[float]:
    if sig.is_float:
        return st.floats(sig.min, sig.max, allow_nan=False).map(_f32).filter(
            lambda v: sig.min <= v <= sig.max
        )
    lo_raw = math.ceil((sig.min - sig.offset) / sig.factor - 1e-9)
    hi_raw = math.floor((sig.max - sig.offset) / sig.factor + 1e-9)
    if sig.factor < 0:
        lo_raw, hi_raw = hi_raw, lo_raw
    # a few seed ranges exceed what the bit width can carry (autofixYaw: +/-160 in 8 signed bits)
    if sig.signed:
        lo_raw = max(lo_raw, -(1 << (sig.length - 1)))
        hi_raw = min(hi_raw, (1 << (sig.length - 1)) - 1)
    else:
        lo_raw, hi_raw = max(lo_raw, 0), min(hi_raw, (1 << sig.length) - 1)
    if sig.factor == 1 and float(sig.offset).is_integer():
        return st.integers(lo_raw, max(lo_raw, hi_raw)).map(lambda r: r + int(sig.offset))
    return st.integers(lo_raw, max(lo_raw, hi_raw)).map(
        lambda r: round(r * sig.factor + sig.offset, 9)
    )
