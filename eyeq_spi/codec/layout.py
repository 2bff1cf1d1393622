"""Construct layouts compiled from ``specs/`` struct variants (decisions D2, D5).

A :class:`Layout` is one struct at one SW version: a construct ``Struct`` built on first use (the
reference codec; bitfields sharing a container, D2, are one integer field split and joined by
precomputed shifts), the ``struct``-based fast twin (:mod:`.layout_fast`) used by
``parse``/``build``, the offset and size of every member, and the E2E plan (every ``crc_16`` in
the struct and its children, inner first, with the byte ranges it covers and its counter).

Decoded values are plain dicts and lists keyed by the seed's member names.
"""

from __future__ import annotations

import contextlib
import struct
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.catalog.messages import Catalog, Crc, Member, StructVariant, SwKey
from eyeq_spi.codec.layout_fast import FastCodec
from eyeq_spi.codec.layout_types import (
    FieldInfo as FieldInfo,  # re-exported: its users import it here
)
from eyeq_spi.errors import LocalProtocolError, SpecError
from eyeq_spi.twins import references_only

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

    # -- values ----------------------------------------------------------------------------
    def post(self, parsed: Any) -> dict[str, Any]:
        """construct Container -> plain dict with bitfields split."""
        out: dict[str, Any] = {}
        for op in self._decode_ops:
            kind = op[0]
            if kind == 0:
                out[op[1]] = parsed[op[1]]
            elif kind == 1:
                out[op[1]] = list(parsed[op[1]])
            elif kind == 2:
                out[op[1]] = op[2].post(parsed[op[1]])
            elif kind == 3:
                child = op[2]
                out[op[1]] = [child.post(item) for item in parsed[op[1]]]
            else:
                word = parsed[op[1]]
                for name, lo, mask in op[2]:
                    out[name] = (word >> lo) & mask
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
                    out[op[1]] = [child.pre(item) for item in items]
                else:
                    word = op[3]  # unused bits set
                    for name, lo, mask in op[2]:
                        value = values[name]
                        if not isinstance(value, int) or not 0 <= value <= mask:
                            raise LocalProtocolError(f"{self.name}.{name}: {value!r} does not fit"
                                                     f" {mask.bit_length()} bit(s)")
                        word |= value << lo
                    out[op[1]] = word
        except KeyError as exc:
            raise LocalProtocolError(f"{self.name}: missing member {exc.args[0]}") from None
        except TypeError as exc:
            raise LocalProtocolError(f"{self.name}: {exc}") from None
        return out

    @property
    def struct(self) -> Any:
        """The compiled construct ``Struct`` (built, with its children's, on first use)."""
        if self._struct is None:
            import construct

            subcons: list[Any] = []
            for key, prim, count, child in self._cons:
                con = (getattr(construct, prim) if prim is not None
                       else child.struct)  # type: ignore[union-attr]
                subcons.append(key / (con if count is None else construct.Array(count, con)))
            struct = construct.Struct(*subcons)
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
        if references_only():
            return self.build_construct(values)
        try:
            return self.fast.encode(values)
        except LocalProtocolError as exc:
            raise LocalProtocolError(f"{self.name}: {exc}") from None

    def parse(self, data: bytes) -> dict[str, Any]:
        if references_only():
            return self.parse_construct(data)
        if len(data) != self.size:
            raise LocalProtocolError(f"{self.name} ({self.sw}) is {self.size} bytes, "
                                     f"got {len(data)}")
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

    # -- E2E ---------------------------------------------------------------------------------
    def resolve(self, path: str, base: int = 0) -> list[tuple[int, int]]:
        """Byte ranges of a covered signal: a member, a dotted path, a whole struct or array."""
        head, _, rest = path.partition(".")
        info = self._by_name.get(head)
        if info is None:
            raise SpecError(f"{self.name}: CRC covers unknown signal {path!r}")
        start = base + info.offset
        if not rest:
            return [(start, info.size)]
        child = self.children.get(head)
        if child is None:
            raise SpecError(f"{self.name}: {head} is not a struct, cannot resolve {path!r}")
        out: list[tuple[int, int]] = []
        for element in range(info.count or 1):
            out += child.resolve(rest, start + element * child.size)
        return out

    def zero_values(self) -> dict[str, Any]:
        """A complete value dict of zeros (0.0 for floats) in this layout's shape."""
        out: dict[str, Any] = {}
        for info in self.fields:
            child = self.children.get(info.name)
            if child is not None:
                out[info.name] = (
                    [child.zero_values() for _ in range(info.count)] if info.count
                    else child.zero_values()
                )
                continue
            zero: Any = 0.0 if info.type in ("real32", "real64") else 0
            out[info.name] = [zero] * info.count if info.count else zero
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

    def _count(self, member: Member, sw: SwKey) -> int | None:
        if member.array is None:
            return None
        if isinstance(member.array, int):
            return member.array
        return self.cat.constant(member.array, sw)

    def _variant(self, name: str, sw: SwKey, stack: tuple[str, ...]) -> StructVariant:
        if name in stack:
            raise SpecError(f"struct {name} contains itself: {' -> '.join(stack)}")
        sdef = self.cat.structs.get(name)
        if sdef is None:
            raise SpecError(f"unknown struct {name}")
        var = sdef.variant_for(sw)
        if var is None:
            raise SpecError(f"struct {name} has no layout for {sw}")
        return var

    def _compile(self, name: str, sw: SwKey, stack: tuple[str, ...]) -> Layout:
        var = self._variant(name, sw, stack)
        plan = _LayoutPlan()
        members = list(var.members)
        index = 0
        while index < len(members):
            member = members[index]
            if member.bits is not None:
                group = _bit_group(members, index)
                plan.add_bit_group(group)
                index += len(group)
                continue
            child = (None if member.type in PRIMITIVE
                     else self._compile(member.type, sw, (*stack, name)))
            plan.add_member(member, self._count(member, sw), child)
            index += 1
        lay = Layout(name, sw, var.key, plan.offset, plan.fields, plan.children)
        lay._cons, lay._decode_ops, lay._encode_ops = plan.subcons, plan.dec, plan.enc
        lay._by_name = {info.name: info for info in plan.fields}
        # E2E plan: children first (their CRCs are inside ours), then our own.
        lay.crc_plan += _child_crc_plans(lay)
        lay.crc_plan += [_own_crc_plan(lay, crc) for crc in var.crcs]
        return lay


def _container(member: Member) -> str:
    """The seed type of a bitfield member's container (uint8 when the spec names none)."""
    return member.type if member.type in PRIMITIVE else "uint8"


def _bit_group(members: list[Member], first: int) -> list[Member]:
    """The bitfield members from ``first`` on that share one container (D2): same container
    type, bits rising."""
    group = [members[first]]
    for member in members[first + 1:]:
        if (member.bits is None or _container(member) != _container(group[0])
                or member.bits[0] <= group[-1].bits[1]):  # type: ignore[index]
            break
        group.append(member)
    return group


@dataclass
class _LayoutPlan:
    """A layout's parts gathered member by member: construct fields, field infos, children and
    the decode/encode operation lists that :meth:`Layout.post` and :meth:`Layout.pre` run."""

    subcons: list[tuple[str, str | None, int | None, Layout | None]] = field(
        default_factory=list)
    fields: list[FieldInfo] = field(default_factory=list)
    children: dict[str, Layout] = field(default_factory=dict)
    dec: list[tuple[Any, ...]] = field(default_factory=list)
    enc: list[tuple[Any, ...]] = field(default_factory=list)
    offset: int = 0
    groups: int = 0

    def add_bit_group(self, group: list[Member]) -> None:
        """One container integer holding ``group``'s bitfields; unused bits are encoded as 1."""
        ctype = _container(group[0])
        con, csize = PRIMITIVE[ctype]
        key = f"_bits{self.groups}"
        self.groups += 1
        self.subcons.append((key, con, None, None))
        used = 0
        parts = []
        for member in group:
            lo, hi = member.bits  # type: ignore[misc]
            mask = (1 << (hi - lo + 1)) - 1
            used |= mask << lo
            parts.append((member.name, lo, mask))
            self.fields.append(FieldInfo(member.name, self.offset, csize, ctype, None,
                                         member.bits, member))
        full = (1 << (8 * csize)) - 1
        self.dec.append((4, key, tuple(parts)))
        self.enc.append((4, key, tuple(parts), full & ~used))
        self.offset += csize

    def add_member(self, member: Member, count: int | None, child: Layout | None) -> None:
        """A primitive member (``child`` None) or a nested struct, alone or ``count`` of them."""
        if child is None:
            con, size = PRIMITIVE[member.type]
            self.subcons.append((member.name, con, count, None))
            kind = 0 if count is None else 1
            self.dec.append((kind, member.name))
            self.enc.append((kind, member.name))
            size *= 1 if count is None else count
        else:
            self.children[member.name] = child
            self.subcons.append((member.name, None, count, child))
            if count is None:
                self.dec.append((2, member.name, child))
                self.enc.append((2, member.name, child))
            else:
                self.dec.append((3, member.name, child))
                self.enc.append((3, member.name, child, count))
            size = child.size * (1 if count is None else count)
        self.fields.append(FieldInfo(member.name, self.offset, size, member.type, count, None,
                                     member))
        self.offset += size


def _child_crc_plans(lay: Layout) -> list[CrcPlan]:
    """The E2E checks inside ``lay``'s child structs, moved to their absolute offsets."""
    plans: list[CrcPlan] = []
    for info in lay.fields:
        sub = lay.children.get(info.name)
        if sub is None or not sub.crc_plan:
            continue
        for element in range(info.count or 1):
            base = info.offset + element * sub.size
            label = info.name if info.count is None else f"{info.name}[{element}]"
            plans += [CrcPlan(
                f"{label}.{inner.path}" if inner.path else label, inner.field,
                base + inner.crc_offset,
                None if inner.counter_offset is None else base + inner.counter_offset,
                inner.counter_size, tuple((base + off, size) for off, size in inner.ranges),
            ) for inner in sub.crc_plan]
    return plans


def _own_crc_plan(lay: Layout, crc: Crc) -> CrcPlan:
    """One E2E check of ``lay`` itself: its CRC and counter fields and the bytes it covers."""
    ranges: list[tuple[int, int]] = []
    for signal in crc.covers:
        ranges += lay.resolve(signal)
    crc_field = lay.field(crc.field)
    counter = lay.field(crc.counter) if crc.counter else None
    return CrcPlan("", crc.field, crc_field.offset, counter.offset if counter else None,
                   counter.size if counter else 0, _merge(ranges))
