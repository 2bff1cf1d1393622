"""A fast path generated from the same layouts as the construct codec.

For one :class:`~eyeq_spi.codec.layout.Layout`: one ``struct.Struct`` over every primitive leaf
and, generated with ``exec`` from ``Layout.fields``, a function that nests the flat tuple into
dicts and one that flattens back. The construct codec stays the reference the tests hold it to."""

from __future__ import annotations

import struct
from typing import Any

from eyeq_spi.codec.layout_types import LayoutShape
from eyeq_spi.errors import LocalProtocolError

FMT = {"uint8": "B", "uint16": "H", "uint32": "I", "uint64": "Q", "int8": "b", "int16": "h",
       "int32": "i", "int64": "q", "real32": "f", "real64": "d", "bool": "B"}


class FastCodec:
    def __init__(self, layout: LayoutShape) -> None:
        self._fmt: list[str] = []
        self._src: list[str] = []
        self._names: dict[int, str] = {}
        self._env: dict[str, Any] = {"LocalProtocolError": LocalProtocolError}
        top = self._gen(layout)
        self.struct = struct.Struct("<" + "".join(self._fmt))
        if self.struct.size != layout.size:
            raise LocalProtocolError(f"fast path of {layout.name}: {self.struct.size} != "
                                     f"{layout.size}")
        exec("\n".join(self._src), self._env)
        self._decode = self._env[f"d_{top}"]
        self._encode = self._env[f"e_{top}"]

    def decode(self, data: bytes) -> dict[str, Any]:
        flat = self.struct.unpack(data)
        out: dict[str, Any] = self._decode(flat, 0)
        return out

    def encode(self, values: dict[str, Any]) -> bytes:
        out: list[Any] = []
        try:
            self._encode(values, out)
            return self.struct.pack(*out)
        except KeyError as exc:
            raise LocalProtocolError(f"missing member {exc.args[0]}") from None
        except (struct.error, TypeError, OverflowError) as exc:  # 1e39 into a real32, ...
            raise LocalProtocolError(f"cannot encode: {exc}") from None

    # -- generation --------------------------------------------------------------------------
    def _gen(self, lay: LayoutShape) -> str:
        """Generate d_<n>(t, o) and e_<n>(v, out) for ``lay``; returns <n>. Leaves are appended
        to the format in byte order, so a struct's leaves are one contiguous run."""
        suffix = str(len(self._names))
        self._names[id(lay)] = suffix
        first = len(self._fmt)
        dec: list[str] = []
        enc: list[str] = []
        seen_groups: set[int] = set()
        for field in lay.fields:
            if field.bits is not None:
                key = field.offset
                if key not in seen_groups:
                    seen_groups.add(key)
                    idx = len(self._fmt) - first
                    self._fmt.append(FMT[field.type])
                    group = [g for g in lay.fields if g.bits is not None and g.offset == key]
                    used = 0
                    parts = []
                    for member in group:
                        assert member.bits is not None
                        lo, hi = member.bits
                        mask = (1 << (hi - lo + 1)) - 1
                        used |= mask << lo
                        dec.append(f"{member.name!r}: (t[o+{idx}] >> {lo}) & {mask}")
                        parts.append(f"_b(v[{member.name!r}], {mask}, {member.name!r}) << {lo}")
                    unused = ((1 << (8 * field.size)) - 1) & ~used
                    enc.append(f"out.append({unused} | " + " | ".join(parts) + ")")
                continue
            child = lay.children.get(field.name)
            idx = len(self._fmt) - first
            if child is None:
                count = field.count or 1
                self._fmt.extend(FMT[field.type] * count)  # one entry per tuple item
                if field.count:
                    dec.append(f"{field.name!r}: list(t[o+{idx}:o+{idx + count}])")
                    enc.append(f"_n(v[{field.name!r}], {count}, {field.name!r}); "
                               f"out.extend(v[{field.name!r}])")
                else:
                    dec.append(f"{field.name!r}: t[o+{idx}]")
                    enc.append(f"out.append(v[{field.name!r}])")
                continue
            before = len(self._fmt)
            cn = self._gen(child)
            per = len(self._fmt) - before  # tuple items of one element
            if field.count:
                # the child generated one element; repeat its formats for the others
                self._fmt.extend(self._fmt[before:] * (field.count - 1))
                dec.append(f"{field.name!r}: [d_{cn}(t, o+{idx}+i*{per}) "
                           f"for i in range({field.count})]")
                enc.append(f"_n(v[{field.name!r}], {field.count}, {field.name!r})")
                enc.append(f"for x in v[{field.name!r}]: e_{cn}(x, out)")
            else:
                dec.append(f"{field.name!r}: d_{cn}(t, o+{idx})")
                enc.append(f"e_{cn}(v[{field.name!r}], out)")
        self._src.append(f"def d_{suffix}(t, o):\n    return {{" + ", ".join(dec) + "}")
        self._src.append(f"def e_{suffix}(v, out):\n" + "".join(f"    {e}\n" for e in enc)
                         + "    return None")
        self._env.setdefault("_b", _bits)
        self._env.setdefault("_n", _count)
        return suffix


def _bits(value: Any, mask: int, name: str) -> int:
    if not isinstance(value, int) or not 0 <= value <= mask:
        raise LocalProtocolError(f"{name}: {value!r} does not fit {mask.bit_length()} bit(s)")
    return value


def _count(items: Any, count: int, name: str) -> None:
    if len(items) != count:
        raise LocalProtocolError(f"{name} needs {count} elements, got {len(items)}")
