"""Application-layer tables of the Lua dissector (decisions A, M, D), built from the codec.

Nothing here knows an offset by heart: every struct layout comes from
:class:`eyeq_spi.codec.message.MessageCodec` (which compiles ``specs/structs``), every enum from
``specs/enums``, every MESP function from ``specs/mesp.yaml``.

Generated Lua (see :mod:`eyeq_spi.wireshark.lua_runtime` for the code that walks it):

- ``S["<struct>"]`` — one row per member, in layout order:
  ``{offset, element size, count (0 = scalar), field, child struct or false, label, flags}``.
  A bitfield's row has its container's offset and size; its field carries the mask (D2).
- ``DASP[data_id]``, ``OTHER[first byte]`` — ``{name=, struct=, size=}``;
- ``MESP[service * 256 + function]`` — ``{name=, req={{type, field, label}...}, rep={...}}``.

Filter names: every member is ``eyeq_spi.<struct type>.<member>``, defined once per
(struct, member) and shared by every array element and every message that contains the struct;
a flag of a flags enum is ``eyeq_spi.<struct>.<member>.<flag>``; a payload is
``eyeq_spi.<payload struct>``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from eyeq_spi.codec.layout import FieldInfo, Layout
from eyeq_spi.codec.mesp import REPLY_BIT, TAG_MASK
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.spec.catalog import MespParam
from eyeq_spi.wireshark.lua_common import (
    FLOAT_FIELD,
    INT_FIELD,
    INT_SIZE,
    FieldRegistry,
    ValueStrings,
    int_field_args,
    lua_int,
    lua_str,
    name_part,
)

MESP_PARAM_FIELD = {"u8": ("uint8", 1), "u16": ("uint16", 2), "u32": ("uint32", 4)}


@dataclass
class AppTables:
    """Lua text for the application layer, in the order it must appear."""

    structs: list[str] = field(default_factory=list)
    messages: list[str] = field(default_factory=list)


class AppGenerator:
    def __init__(self, codec: MessageCodec, fields: FieldRegistry, vs: ValueStrings) -> None:
        self.codec = codec
        self.cat = codec.cat
        self.fields = fields
        self.vs = vs
        self.out = AppTables()
        self._done: set[str] = set()
        self.data_id_names: dict[int, str] = {}
        self.mesp_masks = (TAG_MASK, REPLY_BIT)

    # -- structs -----------------------------------------------------------------------------
    def struct(self, lay: Layout) -> None:
        """Emit ``S[lay.name]`` and, first, everything it needs."""
        if lay.name in self._done:
            return
        self._done.add(lay.name)
        rows: list[str] = []
        for f in lay.fields:
            child = lay.children.get(f.name)
            if child is not None:
                self.struct(child)
            rows.append(self._row(lay, f, child))
        body = ",\n  ".join(rows)
        self.out.structs.append(
            f"-- {lay.name}: {lay.size} bytes (layout {lay.variant})\n"
            f"S[{lua_str(lay.name)}] = {{\n  {body},\n}}"
        )

    def _row(self, lay: Layout, f: FieldInfo, child: Layout | None) -> str:
        count = f.count or 0
        elem = f.size // count if count else f.size
        key = f"{name_part(lay.name)}.{name_part(f.name)}"
        label = lua_str(f.name)
        flags = "nil"
        if child is not None:
            ref = self.fields.add(key, "none", lua_str(f.name), lua_str(self._desc(f, child.name)))
            target = lua_str(child.name)
        else:
            ref, flags = self._scalar(key, lay, f)
            target = "false"
        row = f"{{{f.offset}, {elem}, {count}, {ref}, {target}, {label}"
        return row + (f", {flags}}}" if flags != "nil" else "}")

    @staticmethod
    def _desc(f: FieldInfo, type_name: str | None = None) -> str:
        """The field's blurb: type, bits, units, enum."""
        parts = [type_name or f.type]
        if f.count:
            parts[0] += f"[{f.count}]"
        if f.bits is not None:
            parts.append(f"bits {f.bits[0]}-{f.bits[1]}")
        m = f.member
        if m.units:
            parts.append(f"units {m.units}")
        if m.enum:
            parts.append(f"enum {m.enum}")
        if m.description:
            parts.append(m.description)
        return ", ".join(parts)

    def _scalar(self, key: str, lay: Layout, f: FieldInfo) -> tuple[str, str]:
        m = f.member
        if f.type in FLOAT_FIELD:
            if f.bits is not None:
                raise ValueError(f"{lay.name}.{f.name}: a float cannot be a bitfield")
            ctor = FLOAT_FIELD[f.type][0]
            return self.fields.add(key, ctor, lua_str(f.name), lua_str(self._desc(f))), "nil"
        if f.type not in INT_FIELD:
            raise ValueError(f"{lay.name}.{f.name}: no Wireshark field type for {f.type}")
        mask = None
        width = 8 * INT_SIZE[f.type]
        lo = 0
        if f.bits is not None:
            lo, hi = f.bits
            width = hi - lo + 1
            mask = ((1 << width) - 1) << lo
        vs: str | None = None
        flags = "nil"
        if m.enum:
            enum = self.cat.enums[m.enum]
            if enum.kind == "flags":
                flags = self._flags(key, f, lo, width)
            else:
                vs = self.vs.add(m.enum, {k: v.name for k, v in enum.values.items()})
        elif m.values:
            vs = self.vs.add(key, dict(m.values))
        elif f.type == "bool":
            vs = self.vs.add("bool", {0: "false", 1: "true"})
        args = int_field_args(f.name, "base.DEC", vs, mask, self._desc(f))
        return self.fields.add(key, INT_FIELD[f.type], *args), flags

    def _flags(self, key: str, f: FieldInfo, lo: int, width: int) -> str:
        """One boolean field per flag of a ``kind: flags`` enum, on the member's container."""
        enum = self.cat.enums[f.member.enum or ""]
        container_bits = 8 * INT_SIZE[f.type]
        refs: list[str] = []
        used: set[str] = set()
        for bit, v in sorted(enum.values.items()):
            if bit + v.width > width:
                continue
            sub = name_part(v.name)
            while sub in used:
                sub += "_"
            used.add(sub)
            refs.append(self.fields.add(
                f"{key}.{sub}", "bool", lua_str(v.name), str(container_bits), "nil",
                lua_int(((1 << v.width) - 1) << (lo + bit)),  # a multi-bit field: any bit set
            ))
        return "{" + ", ".join(refs) + "}" if refs else "nil"

    # -- messages ----------------------------------------------------------------------------
    def messages(self) -> None:
        dasp: list[str] = []
        other: list[str] = []
        names: dict[int, str] = {}
        for msg in self.cat.messages:
            if msg.protocol == "DASP" and not msg.exists_in(self.codec.sw):
                continue
            lay = self.codec.layout(msg)
            self.struct(lay)
            key = name_part(lay.name)
            self.fields.add(key, "none", lua_str(msg.payload),
                            lua_str(f"payload of {msg.name}, {lay.size} bytes"))
            entry = (f"{{name={lua_str(msg.name)}, protocol={lua_str(msg.protocol)}, "
                     f"struct={lua_str(lay.name)}, size={lay.size}, "
                     f"field={self.fields.ref(key)}}}")
            if msg.protocol == "DASP":
                names[msg.data_id] = msg.name
                dasp.append(f"DASP[{lua_int(msg.data_id)}] = {entry}")
            else:
                other.append(f"OTHER[{lua_int(msg.data_id)}] = {entry}")
        self.out.messages += dasp + other
        self.data_id_names = names

    def mesp_fields(self) -> None:
        """MESP header fields (M1) and parameter fields (M2, M3)."""
        raw = self.cat.raw["mesp.yaml"]["mesp"]
        counter_mask = (1 << int(raw["tag_counter_bits"])) - 1
        reply_mask = 1 << int(raw["tag_reply_bit"])
        if counter_mask != TAG_MASK or reply_mask != REPLY_BIT:  # the codec must agree
            raise ValueError("specs/mesp.yaml tag bits disagree with eyeq_spi.codec.mesp")
        add = self.fields.add
        add("mesp.service", "uint8", lua_str("Service"), "base.HEX")
        add("mesp.protocol", "uint8", lua_str("Protocol"), "base.HEX")
        add("mesp.service_repeat", "uint8", lua_str("Service (repeated)"), "base.HEX")
        add("mesp.function", "uint8", lua_str("Function"), "base.HEX")
        add("mesp.tag", "uint8", lua_str("Tag"), "base.HEX")
        add("mesp.counter", "uint8", lua_str("Counter"), "base.DEC", "nil",
            lua_int(counter_mask))
        add("mesp.reply", "bool", lua_str("Reply"), "8", "nil", lua_int(reply_mask))
        add("mesp.name", "string", lua_str("Function name"))
        ret = self.vs.add("mesp_ret", {int(k): str(v) for k, v in self.cat.mesp_ret.items()})
        add("mesp.ret", "uint32", lua_str("ret"), "base.DEC", ret)
        add("mesp.length", "uint32", lua_str("Length"), "base.DEC")
        types: dict[str, set[str]] = {}
        for fn in self.cat.mesp:
            for prm in (*fn.request, *fn.reply):
                types.setdefault(prm.name, set()).add(prm.type)
        self.mesp_masks = (counter_mask, reply_mask)
        lines: list[str] = []
        for fn in self.cat.mesp:
            def rows(params: tuple[MespParam, ...], fn_name: str = fn.name) -> str:
                out = []
                for prm in params:
                    key = f"mesp.{name_part(prm.name)}"
                    if len(types[prm.name]) > 1:
                        key = f"mesp.{name_part(fn_name)}.{name_part(prm.name)}"
                    out.append(f"{{{lua_str(prm.type)}, {self._mesp_param(key, prm)}, "
                               f"{lua_str(prm.name)}}}")
                return "{" + ", ".join(out) + "}"

            lines.append(
                f"MESP[{lua_int(fn.service * 256 + fn.function)}] = "
                f"{{name={lua_str(fn.name)}, req={rows(fn.request)}, rep={rows(fn.reply)}}}"
            )
        self.out.messages += lines

    def _mesp_param(self, key: str, prm: MespParam) -> str:
        if prm.type in MESP_PARAM_FIELD:
            return self.fields.add(key, MESP_PARAM_FIELD[prm.type][0], lua_str(prm.name),
                                   "base.DEC")
        if prm.type == "string":
            return self.fields.add(key, "string", lua_str(prm.name))
        if prm.type == "bytes":
            return self.fields.add(key, "bytes", lua_str(prm.name))
        raise ValueError(f"MESP parameter {prm.name}: unknown type {prm.type}")
