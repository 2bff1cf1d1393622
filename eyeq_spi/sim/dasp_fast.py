"""DASP payloads packed in place: a reused bytearray per (message, SW release) that the
scene writes straight into, instead of a value dict that ``MessageCodec.encode_dasp`` then packs.

Theory of operation
-------------------
A :class:`DaspPacker` holds the payload of one DASP message at one SW release as a ``bytearray``
that starts as ``Layout.build(zero_values())`` (bitfield containers with their unused bits set,
D2) and is reused from frame to frame, as the reference reuses its value dict. Its
:class:`StructView` tree mirrors that dict (``in``, ``get``, ``[]``, ``update``); offsets,
formats and bit positions come from the :class:`~eyeq_spi.codec.layout.Layout`, and a write
packs at once with the errors the reference's encoder raises. :meth:`DaspPacker.encode` fills
the rolling counters and CRCs (D5, as :func:`eyeq_spi.codec.e2e.protect`) and prepends the
§7.1.2 DASP header, as ``MessageCodec.encode_dasp`` does."""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from eyeq_spi.codec.e2e import E2EState, compile_protector
from eyeq_spi.codec.layout import INT_RANGE, Layout
from eyeq_spi.codec.layout_fast import FMT
from eyeq_spi.codec.message import DASP_PROTOCOL
from eyeq_spi.errors import EyeqError, LocalProtocolError

# numpy dtypes of the seed's primitive types (little-endian, as layout_fast.FMT's "<" formats)
NP_FMT = {"uint8": "u1", "uint16": "<u2", "uint32": "<u4", "uint64": "<u8", "int8": "i1",
          "int16": "<i2", "int32": "<i4", "int64": "<i8", "real32": "<f4", "real64": "<f8",
          "bool": "u1"}
REAL = ("real32", "real64")
SCALAR, BITS, ARRAY = 0, 1, 2


@dataclass(frozen=True)
class Slot:
    """Where one leaf member lives inside its struct."""

    name: str
    kind: int  # SCALAR, BITS (inside a container) or ARRAY (of a primitive)
    offset: int  # of the member, or of its bitfield container
    type: str  # seed type (of the container for BITS)
    st: struct.Struct
    lo: int = 0  # BITS: lowest bit
    mask: int = 0  # BITS: mask of the value before shifting
    count: int = 0  # ARRAY: element count

    @property
    def real(self) -> bool:
        return self.kind == SCALAR and self.type in REAL

    @property
    def wire(self) -> tuple[float, float]:
        """The values a SCALAR integer slot can hold."""
        return INT_RANGE.get(self.type, (-np.inf, np.inf))


def _slots(lay: Layout) -> dict[str, Slot]:
    out: dict[str, Slot] = {}
    for field in lay.fields:
        if field.name in lay.children:
            continue
        fmt = FMT[field.type]
        if field.bits is not None:
            lo, hi = field.bits
            out[field.name] = Slot(field.name, BITS, field.offset, field.type,
                                   struct.Struct("<" + fmt), lo, (1 << (hi - lo + 1)) - 1)
        elif field.count:
            out[field.name] = Slot(field.name, ARRAY, field.offset, field.type,
                                   struct.Struct("<" + fmt * field.count), count=field.count)
        else:
            out[field.name] = Slot(field.name, SCALAR, field.offset, field.type,
                                   struct.Struct("<" + fmt))
    return out


class StructView:
    """One struct of a :class:`DaspPacker`'s payload, used like its value dict."""

    __slots__ = ("base", "buf", "cache", "done", "kids", "layout", "shadow", "slots", "template")

    def __init__(self, buf: bytearray, lay: Layout, base: int, keep: bool,
                 cache: dict[Any, Any]) -> None:
        self.buf, self.layout, self.base, self.cache = buf, lay, base, cache
        self.template: dict[str, Any] | None = None  # the root's: the reference's template
        self.done: set[Any] = set()  # scene_write._puts_once: constants written since reset
        key = ("slots", id(lay))
        if key not in cache:
            cache[key] = (lay, _slots(lay))
        self.slots: dict[str, Slot] = cache[key][1]
        # the values last written, for a filler that reads one back (calibration.fill_calibration);
        # elements of arrays keep none (only numpy columns write them) and read the buffer
        self.shadow: dict[str, Any] | None = {} if keep else None
        self.kids: dict[str, StructView | list[StructView]] = {}
        for field in lay.fields:
            child = lay.children.get(field.name)
            if child is None:
                continue
            offset = base + field.offset
            self.kids[field.name] = (
                [StructView(buf, child, offset + k * child.size, False, cache)
                 for k in range(field.count)]
                if field.count else StructView(buf, child, offset, keep, cache))

    # -- the dict interface the fillers use --------------------------------------------------
    def __contains__(self, key: object) -> bool:
        return key in self.slots or key in self.kids

    def get(self, key: str, default: Any = None) -> Any:
        kid = self.kids.get(key)
        if kid is not None:
            return kid
        return self[key] if key in self.slots else default

    def __getitem__(self, key: str) -> Any:
        kid = self.kids.get(key)
        if kid is not None:
            return kid
        if self.shadow is not None and key in self.shadow:
            return self.shadow[key]
        slot = self.slots[key]
        if slot.kind == ARRAY:
            return list(slot.st.unpack_from(self.buf, self.base + slot.offset))
        raw = slot.st.unpack_from(self.buf, self.base + slot.offset)[0]
        return (raw >> slot.lo) & slot.mask if slot.kind == BITS else raw

    def __setitem__(self, key: str, value: Any) -> None:
        slot = self.slots.get(key)
        if slot is None:
            kid = self.kids.get(key)
            if isinstance(kid, StructView) and isinstance(value, Mapping):
                kid.assign(value)
            elif isinstance(kid, list) and isinstance(value, list):
                if len(value) != len(kid):
                    raise LocalProtocolError(f"{key} needs {len(kid)} elements, got {len(value)}")
                for view, item in zip(kid, value, strict=True):
                    view.assign(item)
            return  # a member this release lacks: the reference's encoder ignores it too
        offset = self.base + slot.offset
        try:
            if slot.kind == SCALAR:
                slot.st.pack_into(self.buf, offset, value)
            elif slot.kind == BITS:  # layout_fast._bits: the same check, then the container's bits
                if not isinstance(value, int) or not 0 <= value <= slot.mask:
                    raise LocalProtocolError(f"{key}: {value!r} does not fit "
                                             f"{slot.mask.bit_length()} bit(s)")
                container = slot.st.unpack_from(self.buf, offset)[0] & ~(slot.mask << slot.lo)
                slot.st.pack_into(self.buf, offset, container | value << slot.lo)
            else:
                if len(value) != slot.count:
                    raise LocalProtocolError(f"{key} needs {slot.count} elements, got {len(value)}")
                slot.st.pack_into(self.buf, offset, *value)
        except (struct.error, TypeError) as exc:
            raise LocalProtocolError(f"{self.layout.name}.{key}: cannot encode: {exc}") from None
        if self.shadow is not None:
            self.shadow[key] = value

    def update(self, values: Mapping[str, Any]) -> None:
        for key, value in values.items():
            self[key] = value

    def assign(self, values: Mapping[str, Any]) -> None:
        """A whole struct at once (the reference replaces its sub-dict): every member needed."""
        missing = [k for k in (*self.slots, *self.kids) if k not in values]
        if missing:
            raise LocalProtocolError(f"{self.layout.name}: missing member {missing[0]}")
        self.update(values)

    def reset(self) -> None:
        if self.shadow is not None:
            self.shadow.clear()
        self.done.clear()
        for kid in self.kids.values():
            for view in kid if isinstance(kid, list) else (kid,):
                view.reset()


class DaspPacker:
    """The payload of one DASP message at one SW release, packed in place."""

    def __init__(self, layout: Layout, data_id: int) -> None:
        self.layout = layout
        self.template = layout.zero_values()  # the reference's template: its shape picks ranges
        self._zero = layout.build(self.template)
        self.buf = bytearray(self._zero)
        self.cache: dict[Any, Any] = {}
        self.root = StructView(self.buf, layout, 0, True, self.cache)
        self.root.template = self.template
        self._protect = compile_protector(layout)
        self._head = bytes((DASP_PROTOCOL, data_id))

    @classmethod
    def build(cls, layout: Layout, data_id: int) -> DaspPacker | None:
        """A packer, or None when the layout cannot be packed (the caller takes the dict
        path, which reports the problem as it always has)."""
        try:
            return cls(layout, data_id)
        except EyeqError:
            return None

    def reset(self) -> None:
        """Back to the zero template (as the reference's fresh ``zero_values()`` dict)."""
        self.buf[:] = self._zero
        self.root.reset()

    def encode(self, counter: int, e2e: E2EState | None) -> bytes:
        """§7.1.2 header (protocol, data ID, counter, reserved 0) and the protected payload."""
        if not 0 <= counter <= 255:
            raise LocalProtocolError(f"DASP counter {counter} outside 0..255")
        self._protect(self.buf, e2e)
        return self._head + bytes((counter, 0)) + self.buf
