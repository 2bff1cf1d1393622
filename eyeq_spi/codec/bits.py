"""Bit-signal codec for the bit-packed init messages and the EEPROM image (decision I1).

``Start`` counts from bit 0 = LSB of byte 0 (Intel order). ``raw = round((physical - offset) /
factor)`` (or truncated where the spec says ``rounding: truncate``, as Appendix E does for the
EEPROM), two's complement within ``Len`` for signed signals, IEEE binary32 for float signals.
An out-of-range physical value raises :class:`LocalProtocolError` naming the signal and its range.
"""

from __future__ import annotations

import math
import struct
from typing import Any

from eyeq_spi.catalog.messages import (
    Catalog,
    InitMessageDef,
    InitSignal,
    InitVariant,
    SwKey,
    catalog,
)
from eyeq_spi.errors import LocalProtocolError, SpecError

_EPS = 1e-9


class BitSignalCodec:
    def __init__(self, message: InitMessageDef, variant: InitVariant) -> None:
        self.message = message
        self.variant = variant
        self.signals = {s.name: s for s in variant.signals}
        self.length = variant.length_bytes

    @classmethod
    def for_message(
        cls, name: str, sw: str | None = None, cat: Catalog | None = None
    ) -> BitSignalCodec:
        cat = cat or catalog()
        msg = cat.init_messages.get(name)
        if msg is None:
            by_id = [m for m in cat.init_messages.values() if m.id == _as_int(name)]
            if not by_id:
                raise SpecError(f"unknown init message {name}")
            msg = by_id[0]
        key: SwKey = cat.sw(sw)
        var = msg.variant_for(key)
        if var is None:
            raise SpecError(f"{msg.name} has no bit table for {key} (the seed prints none)")
        return cls(msg, var)

    # -- one signal --------------------------------------------------------------------------
    def to_raw(self, sig: InitSignal, physical: float) -> int:
        if isinstance(physical, bool) or not isinstance(physical, (int, float)) or (
            isinstance(physical, float) and math.isnan(physical)
        ):
            raise LocalProtocolError(f"{sig.name}: {physical!r} is not a number")
        lo, hi = sig.min, sig.max
        tol = max(abs(sig.factor) / 2, _EPS) if not sig.is_float else _EPS
        if physical < lo - tol or physical > hi + tol:
            unit = f" {sig.units}" if sig.units else ""
            raise LocalProtocolError(
                f"{self.message.name}.{sig.name} = {physical}{unit} is outside its range "
                f"[{lo:g}, {hi:g}]{unit}"
            )
        if sig.is_float:
            return int.from_bytes(struct.pack("<f", physical), "little")
        if _exact(sig) and isinstance(physical, int):
            raw = physical - int(sig.offset)  # integer signal: no float on the way (128-bit IDs)
        else:
            scaled = (physical - sig.offset) / sig.factor
            if self.message.rounding == "truncate":
                raw = math.trunc(scaled + (_EPS if scaled >= 0 else -_EPS))
            else:
                raw = round(scaled)
            raw = _into_range(raw, (lo - sig.offset) / sig.factor, (hi - sig.offset) / sig.factor)
        bits = sig.length
        if sig.signed:
            rmin, rmax = -(1 << (bits - 1)), (1 << (bits - 1)) - 1
        else:
            rmin, rmax = 0, (1 << bits) - 1
        if not rmin <= raw <= rmax:
            raise LocalProtocolError(
                f"{self.message.name}.{sig.name}: raw {raw} does not fit {bits} "
                f"{'signed' if sig.signed else 'unsigned'} bits"
            )
        return raw & ((1 << bits) - 1)

    def to_physical(self, sig: InitSignal, raw: int) -> float:
        if sig.is_float:
            return float(struct.unpack("<f", raw.to_bytes(4, "little"))[0])
        if sig.signed and raw >> (sig.length - 1):
            raw -= 1 << sig.length
        if _exact(sig):
            return raw + int(sig.offset)
        value = raw * sig.factor + sig.offset
        return float(round(value, 9))

    # -- whole message -----------------------------------------------------------------------
    def encode(self, values: dict[str, Any] | None = None) -> bytes:
        """Pack physical ``values``; signals not given take their initial value."""
        values = dict(values or {})
        unknown = set(values) - set(self.signals)
        if unknown:
            raise LocalProtocolError(f"{self.message.name}: unknown signal(s) {sorted(unknown)}")
        word = 0
        for sig in self.variant.signals:
            phys = values.get(sig.name, sig.initial)
            word |= self.to_raw(sig, phys) << sig.start
        return word.to_bytes(self.length, "little")

    def decode_raw(self, data: bytes) -> dict[str, int]:
        if len(data) != self.length:
            raise LocalProtocolError(f"{self.message.name} is {self.length} bytes, got {len(data)}")
        word = int.from_bytes(data, "little")
        return {s.name: (word >> s.start) & ((1 << s.length) - 1) for s in self.variant.signals}

    def decode(self, data: bytes) -> dict[str, float]:
        raw = self.decode_raw(data)
        return {s.name: self.to_physical(s, raw[s.name]) for s in self.variant.signals}

    def check(self, data: bytes) -> list[str]:
        """Problems with received bytes: wrong length, values outside their ranges."""
        try:
            values = self.decode(data)
        except LocalProtocolError as exc:
            return [str(exc)]
        out = []
        for sig in self.variant.signals:
            value = values[sig.name]
            tol = max(abs(sig.factor) / 2, _EPS)
            if ((isinstance(value, float) and math.isnan(value))
                    or value < sig.min - tol or value > sig.max + tol):
                out.append(f"{self.message.name}.{sig.name} = {value:g} "
                           f"outside [{sig.min:g}, {sig.max:g}]")
        return out


def _into_range(raw: int, q_lo: float, q_hi: float) -> int:
    """A value inside the range's half-step tolerance must not round to a raw value whose
    physical value lies outside the range (0.5 for a [1, 1] signal rounded to 0): snap it to the
    nearest raw value inside the range, when the range holds one."""
    if not (math.isfinite(q_lo) and math.isfinite(q_hi)):
        return raw
    if q_lo > q_hi:  # a negative factor
        q_lo, q_hi = q_hi, q_lo
    first, last = math.ceil(q_lo - _EPS), math.floor(q_hi + _EPS)
    if first > last:
        return raw
    return min(max(raw, first), last)


def _exact(sig: InitSignal) -> bool:
    """Factor 1 and an integer offset: raw and physical are the same integers."""
    return (not sig.is_float and sig.factor == 1 and float(sig.offset).is_integer())


def _as_int(text: str) -> int | None:
    try:
        return int(text, 0)
    except ValueError:
        return None
