"""Construct layouts compiled from ``specs/`` struct variants (decisions D2, D5).

A :class:`Layout` is one struct at one SW version:

- a compiled construct ``Struct`` for the byte layout, built on first use of ``struct`` (the
  fast path, ``spec list`` and ``spec show`` never need it, and construct costs start-up
  time). Bitfield members that share a container
  (D2) appear in it as one integer field; splitting and joining them is plain shifting done by
  precomputed operation lists, so no ``BitStruct`` (uncompilable, slow) is on the hot path;
- a ``struct``-based fast path generated from the same fields (:mod:`.layout_fast`), used by
  ``parse``/``build``; the construct codec (``parse_construct``/``build_construct``) is the
  reference the tests hold it to;
- the offset and size of every member, used for CRC coverage and for ``spec show``;
- an E2E plan: every ``crc_16`` in the struct and its children, inner first, with the absolute
  byte ranges it covers and where its rolling counter lives.

Decoded values are plain dicts (nested structs) and lists (arrays), keyed by the seed's member
names; bitfield members appear as ints under their own names.
"""

from __future__ import annotations

import contextlib
import struct
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.catalog.messages import Catalog, Member, SwKey
from eyeq_spi.codec.layout_fast import FastCodec
from eyeq_spi.codec.layout_types import (
    FieldInfo as FieldInfo,  # re-exported: its users import it here
)
from eyeq_spi.crc import crc16
from eyeq_spi.errors import LocalProtocolError, SpecError
from eyeq_spi.twins import exact

PRIMITIVE = {  # seed type -> (construct field name, bytes)
    "uint8": ("Int8ul", 1), "uint16": ("Int16ul", 2), "uint32": ("Int32ul", 4),
    "uint64": ("Int64ul", 8), "int8": ("Int8sl", 1), "int16": ("Int16sl", 2),
    "int32": ("Int32sl", 4), "int64": ("Int64sl", 8), "real32": ("Float32l", 4),
    "real64": ("Float64l", 8), "bool": ("Int8ul", 1),
}
INT_RANGE = {
    "uint8": (0, 0xFF), "uint16": (0, 0xFFFF), "uint32": (0, 0xFFFFFFFF),
    "uint64": (0, 0xFFFFFFFFFFFFFFFF), "int8": (-0x80, 0x7F), "int16": (-0x8000, 0x7FFF),
    "int32": (-0x80000000, 0x7FFFFFFF), "int64": (-0x8000000000000000, 0x7FFFFFFFFFFFFFFF),
    "bool": (0, 0xFF),
}


@dataclass(frozen=True)
class CrcPlan:
    """An E2E check laid out (D5): its CRC, counter and covered byte ranges in the struct."""

    path: str  # e.g. "visObs[3]" or "" for this struct
    field: str
    crc_offset: int
    counter_offset: int | None
    counter_size: int
    ranges: tuple[tuple[int, int], ...]  # (offset, size) serialised in order


@dataclass
class Layout:
    """A struct's byte layout in one SW release: fields, children, E2E plan, codecs."""

    name: str
    sw: SwKey
    variant: SwKey
    size: int
    fields: list[FieldInfo]
    children: dict[str, Layout]
    crc_plan: list[CrcPlan] = field(default_factory=list)
    # (member or bit-group key, construct field name or None for a child struct, count, child)
    _cons: list[tuple[str, str | None, int | None, Layout | None]] = field(default_factory=list)
    _struct: Any = None
    _decode_ops: list[tuple[Any, ...]] = field(default_factory=list)
    _encode_ops: list[tuple[Any, ...]] = field(default_factory=list)
    _by_name: dict[str, FieldInfo] = field(default_factory=dict)
    _fast: FastCodec | None = None
    _verify: Any = None  # the generated E2E verifier (codec.e2e.compile_verifier)

    # -- values ----------------------------------------------------------------------------
    def post(self, c: Any) -> dict[str, Any]:
        """construct Container -> plain dict with bitfields split."""
        out: dict[str, Any] = {}
        for op in self._decode_ops:
            kind = op[0]
            if kind == 0:
                out[op[1]] = c[op[1]]
            elif kind == 1:
                out[op[1]] = list(c[op[1]])
            elif kind == 2:
                out[op[1]] = op[2].post(c[op[1]])
            elif kind == 3:
                child = op[2]
                out[op[1]] = [child.post(x) for x in c[op[1]]]
            else:
                v = c[op[1]]
                for name, lo, mask in op[2]:
                    out[name] = (v >> lo) & mask
        return out

    def pre(self, values: dict[str, Any]) -> dict[str, Any]:
        """plain dict -> construct input, joining bitfields (unused bits = 1, D2)."""
        out: dict[str, Any] = {}
        try:
            for op in self._encode_ops:
                kind = op[0]
                if kind in (0, 1):
                    out[op[1]] = values[op[1]]
                elif kind == 2:
                    out[op[1]] = op[2].pre(values[op[1]])
                elif kind == 3:
                    child = op[2]
                    items = values[op[1]]
                    if len(items) != op[3]:
                        raise LocalProtocolError(
                            f"{self.name}.{op[1]} needs {op[3]} elements, got {len(items)}"
                        )
                    out[op[1]] = [child.pre(x) for x in items]
                else:
                    v = op[3]  # unused bits set
                    for name, lo, mask in op[2]:
                        x = values[name]
                        if not isinstance(x, int) or not 0 <= x <= mask:
                            raise LocalProtocolError(
                                f"{self.name}.{name}: {x!r} does not fit {mask.bit_length()} bit(s)"
                            )
                        v |= x << lo
                    out[op[1]] = v
        except KeyError as exc:
            raise LocalProtocolError(f"{self.name}: missing member {exc.args[0]}") from None
        except TypeError as exc:
            raise LocalProtocolError(f"{self.name}: {exc}") from None
        return out

    @property
    def struct(self) -> Any:
        """The compiled construct ``Struct`` (built, with its children's, on first use)."""
        if self._struct is None:
            import construct as c

            subcons: list[Any] = []
            for key, prim, count, child in self._cons:
                con = getattr(c, prim) if prim is not None else child.struct  # type: ignore[union-attr]
                subcons.append(key / (con if count is None else c.Array(count, con)))
            struct = c.Struct(*subcons)
            with contextlib.suppress(Exception):  # construct cannot compile it: run uncompiled
                struct = struct.compile()
            self._struct = struct
        return self._struct

    @property
    def fast(self) -> FastCodec:
        """The ``struct``-based path generated from this layout (built on first use)."""
        if self._fast is None:
            self._fast = FastCodec(self)
        return self._fast

    def build(self, values: dict[str, Any]) -> bytes:
        if exact():
            return self.build_construct(values)
        try:
            return self.fast.encode(values)
        except LocalProtocolError as exc:
            raise LocalProtocolError(f"{self.name}: {exc}") from None

    def parse(self, data: bytes) -> dict[str, Any]:
        if len(data) != self.size:
            raise LocalProtocolError(f"{self.name} ({self.sw}) is {self.size} bytes, "
                                     f"got {len(data)}")
        if exact():
            return self.post(self.struct.parse(data))
        return self.fast.decode(data)

    # The construct codec: the reference the fast path is tested against.
    def build_construct(self, values: dict[str, Any]) -> bytes:
        from construct.core import ConstructError

        try:
            return bytes(self.struct.build(self.pre(values)))
        except (ConstructError, ValueError, OverflowError, TypeError, struct.error) as exc:
            # (construct's compiled builders let struct's own errors through)
            raise LocalProtocolError(f"{self.name}: cannot encode: {exc}") from None

    def parse_construct(self, data: bytes) -> dict[str, Any]:
        if len(data) != self.size:
            raise LocalProtocolError(f"{self.name} ({self.sw}) is {self.size} bytes, "
                                     f"got {len(data)}")
        return self.post(self.struct.parse(data))

    def field(self, name: str) -> FieldInfo:
        return self._by_name[name]

    def find_field(self, name: str) -> FieldInfo | None:
        """The member ``name``, or None where this release's layout has none."""
        return self._by_name.get(name)

    # -- E2E ---------------------------------------------------------------------------------
    def resolve(self, path: str, base: int = 0) -> list[tuple[int, int]]:
        """Byte ranges of a covered signal: a member, a dotted path, a whole struct or array."""
        head, _, rest = path.partition(".")
        f = self._by_name.get(head)
        if f is None:
            raise SpecError(f"{self.name}: CRC covers unknown signal {path!r}")
        start = base + f.offset
        if not rest:
            return [(start, f.size)]
        child = self.children.get(head)
        if child is None:
            raise SpecError(f"{self.name}: {head} is not a struct, cannot resolve {path!r}")
        out: list[tuple[int, int]] = []
        for i in range(f.count or 1):
            out += child.resolve(rest, start + i * child.size)
        return out

    def zero_values(self) -> dict[str, Any]:
        """A complete value dict of zeros (0.0 for floats) in this layout's shape."""
        out: dict[str, Any] = {}
        for f in self.fields:
            child = self.children.get(f.name)
            if child is not None:
                out[f.name] = (
                    [child.zero_values() for _ in range(f.count)] if f.count
                    else child.zero_values()
                )
                continue
            zero: Any = 0.0 if f.type in ("real32", "real64") else 0
            out[f.name] = [zero] * f.count if f.count else zero
        return out


def _merge(ranges: list[tuple[int, int]]) -> tuple[tuple[int, int], ...]:
    out: list[tuple[int, int]] = []
    for off, size in ranges:
        if out and out[-1][0] + out[-1][1] == off:
            out[-1] = (out[-1][0], out[-1][1] + size)
        else:
            out.append((off, size))
    return tuple(out)


class LayoutCache:
    """Compiles layouts on demand, one per (struct, SW version)."""

    def __init__(self, cat: Catalog) -> None:
        self.cat = cat
        self._cache: dict[tuple[str, SwKey], Layout] = {}

    def get(self, name: str, sw: SwKey) -> Layout:
        key = (name, sw)
        lay = self._cache.get(key)
        if lay is None:
            lay = self._compile(name, sw, ())
            self._cache[key] = lay
        return lay

    def _count(self, m: Member, sw: SwKey) -> int | None:
        if m.array is None:
            return None
        if isinstance(m.array, int):
            return m.array
        return self.cat.constant(m.array, sw)

    def _compile(self, name: str, sw: SwKey, stack: tuple[str, ...]) -> Layout:
        if name in stack:
            raise SpecError(f"struct {name} contains itself: {' -> '.join(stack)}")
        sdef = self.cat.structs.get(name)
        if sdef is None:
            raise SpecError(f"unknown struct {name}")
        var = sdef.variant_for(sw)
        if var is None:
            raise SpecError(f"struct {name} has no layout for {sw}")
        subcons: list[tuple[str, str | None, int | None, Layout | None]] = []
        fields: list[FieldInfo] = []
        children: dict[str, Layout] = {}
        dec: list[tuple[Any, ...]] = []
        enc: list[tuple[Any, ...]] = []
        offset = 0
        members = list(var.members)
        i = 0
        ngroup = 0
        while i < len(members):
            m = members[i]
            if m.bits is not None:
                ctype = m.type if m.type in PRIMITIVE else "uint8"
                con, csize = PRIMITIVE[ctype]
                group = [m]
                j = i + 1
                while (
                    j < len(members)
                    and members[j].bits is not None
                    and (members[j].type if members[j].type in PRIMITIVE else "uint8") == ctype
                    and members[j].bits[0] > group[-1].bits[1]  # type: ignore[index]
                ):
                    group.append(members[j])
                    j += 1
                key = f"_bits{ngroup}"
                ngroup += 1
                subcons.append((key, con, None, None))
                used = 0
                parts = []
                for g in group:
                    lo, hi = g.bits  # type: ignore[misc]
                    mask = (1 << (hi - lo + 1)) - 1
                    used |= mask << lo
                    parts.append((g.name, lo, mask))
                    fields.append(FieldInfo(g.name, offset, csize, ctype, None, g.bits, g))
                full = (1 << (8 * csize)) - 1
                dec.append((4, key, tuple(parts)))
                enc.append((4, key, tuple(parts), full & ~used))
                offset += csize
                i = j
                continue
            count = self._count(m, sw)
            if m.type in PRIMITIVE:
                con, size = PRIMITIVE[m.type]
                subcons.append((m.name, con, count, None))
                if count is None:
                    dec.append((0, m.name))
                    enc.append((0, m.name))
                else:
                    dec.append((1, m.name))
                    enc.append((1, m.name))
                    size *= count
            else:
                child = self._compile(m.type, sw, (*stack, name))
                children[m.name] = child
                subcons.append((m.name, None, count, child))
                if count is None:
                    dec.append((2, m.name, child))
                    enc.append((2, m.name, child))
                    size = child.size
                else:
                    dec.append((3, m.name, child))
                    enc.append((3, m.name, child, count))
                    size = child.size * count
            fields.append(FieldInfo(m.name, offset, size, m.type, count, None, m))
            offset += size
            i += 1
        lay = Layout(name, sw, var.key, offset, fields, children)
        lay._cons, lay._decode_ops, lay._encode_ops = subcons, dec, enc
        lay._by_name = {f.name: f for f in fields}
        # E2E plan: children first (their CRCs are inside ours), then our own.
        for f in fields:
            sub = children.get(f.name)
            if sub is None or not sub.crc_plan:
                continue
            for k in range(f.count or 1):
                base = f.offset + k * sub.size
                label = f.name if f.count is None else f"{f.name}[{k}]"
                for p in sub.crc_plan:
                    lay.crc_plan.append(CrcPlan(
                        f"{label}.{p.path}" if p.path else label, p.field,
                        base + p.crc_offset,
                        None if p.counter_offset is None else base + p.counter_offset,
                        p.counter_size, tuple((base + o, s) for o, s in p.ranges),
                    ))
        for crc in var.crcs:
            ranges: list[tuple[int, int]] = []
            for sig in crc.covers:
                ranges += lay.resolve(sig)
            cf = lay.field(crc.field)
            counter = lay.field(crc.counter) if crc.counter else None
            lay.crc_plan.append(CrcPlan(
                "", crc.field, cf.offset, counter.offset if counter else None,
                counter.size if counter else 0, _merge(ranges),
            ))
        return lay


def compute_crc(buf: bytes | bytearray, plan: CrcPlan) -> int:
    return crc16(b"".join(bytes(buf[o : o + s]) for o, s in plan.ranges))
