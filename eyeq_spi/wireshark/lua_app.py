"""Application-layer tables of the Lua dissector (decisions A, M, D), for every SW release.

Every layout comes from :class:`eyeq_spi.codec.message.MessageCodec`, every enum from
``specs/enums``, every MESP function from ``specs/mesp.yaml``. Generated Lua:

- ``S["<struct>#<n>"]``: one table per distinct layout, one row per member
  ``{offset, element size, count (0 = scalar), field, child layout or false, label, flags,
  bits, value names}``; a bitfield row has its container's offset and size and its field the
  mask (D2), or ``bits = {shift, mask}`` and ``value names`` where releases differ;
- ``MSG[i]``, ``DASP_R[release][data_id]``, ``OTHER_R[release][first byte]`` and
  ``SIZES[release][data_id]`` (the release fit, D4);
- ``MESP[service * 256 + function]``: ``{name=, req={{type, field, label}...}, rep={...}}``.

Filter names are ``eyeq_spi.<struct type>.<member>`` (docs/wireshark.md); where releases differ
the field takes the widest integer type and drops what they do not share (mask, enum)."""

from __future__ import annotations

from dataclasses import dataclass, field

from eyeq_spi.catalog.messages import MespParam, MessageDef, SwKey
from eyeq_spi.codec.layout import FieldInfo, Layout
from eyeq_spi.codec.mesp import REPLY_BIT, TAG_MASK
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.errors import EyeqError, SpecError
from eyeq_spi.wireshark.lua_common import (
    FLOAT_FIELD,
    INT_FIELD,
    INT_SIZE,
    FieldRegistry,
    ValueStrings,
    lua_int,
    lua_str,
    name_part,
    value_table,
)

MESP_PARAM_FIELD = {"u8": ("uint8", 1), "u16": ("uint16", 2), "u32": ("uint32", 4)}
_INT_WIDTH = {"8": 1, "16": 2, "32": 4, "64": 8}


@dataclass(frozen=True)
class MemberField:
    """One release's view of a ProtoField: what ``ProtoField.<ctor>`` would be called with."""

    ctor: str
    label: str
    desc: str
    vs: str | None = None  # value_string name (``E[...]``)
    mask: int | None = None
    flags: tuple[tuple[str, str, int, int], ...] = ()  # (key, label, container bits, mask)


@dataclass(frozen=True)
class Merged:
    """The field every release shares, after :func:`merge`."""

    spec: MemberField
    ref: str


def merge(key: str, specs: list[MemberField]) -> MemberField:
    """One definition for all releases (``specs`` oldest first): the widest integer type, the
    mask and enum only where every release has the same, the newest description, the flag
    fields of every release."""
    ctors = {spec.ctor for spec in specs}
    ctor = specs[-1].ctor
    if len(ctors) > 1:
        kinds = {c.rstrip("0123456789") for c in ctors}
        if len(kinds) != 1 or kinds.pop() not in ("uint", "int"):
            raise SpecError(f"specs/structs field eyeq_spi.{key}: types {sorted(ctors)} cannot "
                            "share a Wireshark field")
        ctor = max(ctors, key=lambda c: _INT_WIDTH[c.lstrip("uint")])
    masks = {spec.mask for spec in specs}
    vss = {spec.vs for spec in specs}
    flags: dict[str, tuple[str, str, int, int]] = {}
    for spec in specs:  # every release's flags get a field; a row adds its own release's
        for flag in spec.flags:
            if flags.setdefault(flag[0], flag) != flag:
                raise SpecError(f"specs/structs flag field eyeq_spi.{flag[0]}: differs between "
                                "releases")
    return MemberField(ctor, specs[-1].label, specs[-1].desc,
                       vss.pop() if len(vss) == 1 else None,
                       masks.pop() if len(masks) == 1 else None, tuple(flags.values()))


@dataclass
class AppTables:
    """Lua text for the application layer, in the order it must appear."""

    structs: list[str] = field(default_factory=list)
    messages: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class _Row:
    fi: FieldInfo
    key: str
    child: Layout | None
    spec: MemberField


class AppGenerator:
    def __init__(self, codecs: dict[SwKey, MessageCodec], fields: FieldRegistry,
                 vs: ValueStrings) -> None:
        self.codecs = codecs  # oldest release first
        self.releases = list(codecs)
        self.cat = next(iter(codecs.values())).cat
        self.fields = fields
        self.vs = vs
        self.out = AppTables()
        self.data_id_names: dict[int, str] = {}
        self._specs: dict[str, list[MemberField]] = {}
        self._merged: dict[str, Merged] = {}
        self._struct_keys: dict[str, str] = {}  # emitted rows text -> S key
        self._layout_keys: dict[int, str] = {}  # id(Layout) -> S key
        self._count: dict[str, int] = {}
        self._layouts: list[Layout] = []  # kept alive: _layout_keys is keyed by id()

    # -- member fields --------------------------------------------------------------------------
    @staticmethod
    def _desc(info: FieldInfo, type_name: str | None = None) -> str:
        """The field's blurb: type, bits, units, enum."""
        parts = [type_name or info.type]
        if info.count:
            parts[0] += f"[{info.count}]"
        if info.bits is not None:
            parts.append(f"bits {info.bits[0]}-{info.bits[1]}")
        member = info.member
        if member.units:
            parts.append(f"units {member.units}")
        if member.enum:
            parts.append(f"enum {member.enum}")
        if member.description:
            parts.append(member.description)
        return ", ".join(parts)

    def _member(self, lay: Layout, info: FieldInfo, child: Layout | None) -> MemberField:
        if child is not None:
            return MemberField("none", info.name, self._desc(info, child.name))
        member = info.member
        if info.type in FLOAT_FIELD:
            if info.bits is not None:
                raise SpecError(f"specs/structs {lay.name}.{info.name}: a float cannot be a "
                                "bitfield")
            return MemberField(FLOAT_FIELD[info.type], info.name, self._desc(info))
        if info.type not in INT_FIELD:
            raise SpecError(f"specs/structs {lay.name}.{info.name}: no Wireshark field type for "
                            f"{info.type}")
        mask = None
        width = 8 * INT_SIZE[info.type]
        lo = 0
        if info.bits is not None:
            lo, hi = info.bits
            width = hi - lo + 1
            mask = ((1 << width) - 1) << lo
        vs: str | None = None
        flags: tuple[tuple[str, str, int, int], ...] = ()
        key = f"{name_part(lay.name)}.{name_part(info.name)}"
        if member.enum:
            enum = self.cat.enums[member.enum]
            if enum.kind == "flags":
                flags = self._flags(key, info, lo, width)
            else:
                vs = self.vs.add(member.enum, {k: v.name for k, v in enum.values.items()})
        elif member.values:
            vs = self.vs.add(key, dict(member.values))
        elif info.type == "bool":
            vs = self.vs.add("bool", {0: "false", 1: "true"})
        return MemberField(INT_FIELD[info.type], info.name, self._desc(info), vs, mask, flags)

    def _flags(self, key: str, info: FieldInfo, lo: int,
               width: int) -> tuple[tuple[str, str, int, int], ...]:
        """One boolean field per flag of a ``kind: flags`` enum, on the member's container."""
        enum = self.cat.enums[info.member.enum or ""]
        container_bits = 8 * INT_SIZE[info.type]
        out: list[tuple[str, str, int, int]] = []
        used: set[str] = set()
        for bit, entry in sorted(enum.values.items()):
            if bit + entry.width > width:
                continue
            sub = name_part(entry.name)
            while sub in used:
                sub += "_"
            used.add(sub)
            # a multi-bit field: any bit set
            out.append((f"{key}.{sub}", entry.name, container_bits,
                        ((1 << entry.width) - 1) << (lo + bit)))
        return tuple(out)

    def _collect(self, lay: Layout) -> list[_Row]:
        rows = []
        for info in lay.fields:
            child = lay.children.get(info.name)
            if child is not None:
                self._collect(child)
            key = f"{name_part(lay.name)}.{name_part(info.name)}"
            spec = self._member(lay, info, child)
            specs = self._specs.setdefault(key, [])
            if spec not in specs:
                specs.append(spec)
            rows.append(_Row(info, key, child, spec))
        return rows

    def _register(self, key: str) -> Merged:
        done = self._merged.get(key)
        if done is not None:
            return done
        spec = merge(key, self._specs[key])
        args = [lua_str(spec.label)]
        if spec.ctor == "none" or spec.ctor in ("float", "double"):
            args.append(lua_str(spec.desc))
        else:
            args += ["base.DEC", spec.vs or "nil", lua_int(spec.mask) if spec.mask else "nil",
                     lua_str(spec.desc)]
        ref = self.fields.add(key, spec.ctor, *args)
        for fkey, label, bits, mask in spec.flags:
            self.fields.add(fkey, "bool", lua_str(label), str(bits), "nil", lua_int(mask))
        merged = self._merged[key] = Merged(spec, ref)
        return merged

    # -- structs -----------------------------------------------------------------------------
    def struct(self, lay: Layout) -> str:
        """The ``S`` key of ``lay``, emitting it and, first, everything it needs."""
        known = self._layout_keys.get(id(lay))
        if known is not None:
            return known
        rows: list[str] = []
        for row in self._collect(lay):
            info = row.fi
            count = info.count or 0
            elem = info.size // count if count else info.size
            merged = self._register(row.key)
            target = lua_str(self.struct(row.child)) if row.child is not None else "false"
            cells = [str(info.offset), str(elem), str(count), merged.ref, target,
                     lua_str(info.name)]
            extra = ["nil", "nil", "nil"]
            if row.spec.flags:
                extra[0] = "{" + ", ".join(self.fields.ref(k) for k, *_ in row.spec.flags) + "}"
            if row.spec.mask is not None and merged.spec.mask is None:
                lo = (row.spec.mask & -row.spec.mask).bit_length() - 1
                extra[1] = f"{{{lo}, {lua_int(row.spec.mask >> lo)}}}"
            if row.spec.vs is not None and merged.spec.vs is None:
                extra[2] = row.spec.vs
            while extra and extra[-1] == "nil":
                extra.pop()
            cells += extra
            rows.append("{" + ", ".join(cells) + "}")
        body = ",\n  ".join(rows)
        seen = self._count.get(lay.name, 0)
        skey = self._struct_keys.get(lay.name + "\n" + body)
        if skey is None:
            skey = f"{lay.name}#{seen}"
            self._count[lay.name] = seen + 1
            self._struct_keys[lay.name + "\n" + body] = skey
            self.out.structs.append(
                f"-- {lay.name}: {lay.size} bytes (layout {lay.variant})\n"
                f"S[{lua_str(skey)}] = {{\n  {body},\n}}")
        self._layout_keys[id(lay)] = skey
        self._layouts.append(lay)
        return skey

    # -- messages ----------------------------------------------------------------------------
    def _layouts_of(self, msg: MessageDef) -> list[tuple[int, Layout]]:
        out = []
        for ri, (sw, codec) in enumerate(self.codecs.items(), 1):
            if msg.protocol == "DASP" and not msg.exists_in(sw):
                continue
            try:
                out.append((ri, codec.layout(msg)))
            except EyeqError:  # a layout this release cannot build: the message is unknown there
                continue
        return out

    def messages(self) -> None:
        per_release: dict[int, list[str]] = {ri: [] for ri in range(1, len(self.releases) + 1)}
        entries: dict[tuple[str, str, int], str] = {}
        lines: list[str] = []
        names: dict[int, str] = {}
        sizes: dict[int, dict[int, int]] = {ri: {} for ri in per_release}
        found = [(msg, self._layouts_of(msg)) for msg in self.cat.messages]
        for msg, lays in found:  # collect every release's view of every field first
            for _, lay in lays:
                self._collect(lay)
            self._specs.setdefault(name_part(msg.payload), []).append(
                MemberField("none", msg.payload, f"payload of {msg.name}"))
        for msg, lays in found:
            for ri, lay in lays:
                skey = self.struct(lay)
                key = name_part(lay.name)
                ref = self._register(key).ref
                ident = (msg.name, skey, lay.size)
                var = entries.get(ident)
                if var is None:
                    var = f"MSG[{len(entries) + 1}]"
                    entries[ident] = var
                    lines.append(f"{var} = {{name={lua_str(msg.name)}, "
                                 f"protocol={lua_str(msg.protocol)}, struct={lua_str(skey)}, "
                                 f"size={lay.size}, field={ref}}}")
                table = "DASP_R" if msg.protocol == "DASP" else "OTHER_R"
                per_release[ri].append(f"{table}[{ri}][{lua_int(msg.data_id)}] = {var}")
                if msg.protocol == "DASP":
                    names[msg.data_id] = msg.name
                    sizes[ri][msg.data_id] = lay.size
        self.out.messages += lines
        for ri, rows in per_release.items():
            self.out.messages.append(f"DASP_R[{ri}], OTHER_R[{ri}] = {{}}, {{}}")
            self.out.messages += rows
            self.out.messages.append(f"SIZES[{ri}] = {value_table_int(sizes[ri])}")
        self.data_id_names = names

    def mesp_fields(self) -> None:
        """MESP header fields (M1) and parameter fields (M2, M3)."""
        add = self.fields.add
        add("mesp.service", "uint8", lua_str("Service"), "base.HEX")
        add("mesp.protocol", "uint8", lua_str("Protocol"), "base.HEX")
        add("mesp.service_repeat", "uint8", lua_str("Service (repeated)"), "base.HEX")
        add("mesp.function", "uint8", lua_str("Function"), "base.HEX")
        add("mesp.tag", "uint8", lua_str("Tag"), "base.HEX")
        add("mesp.counter", "uint8", lua_str("Counter"), "base.DEC", "nil",
            lua_int(TAG_MASK))
        add("mesp.reply", "bool", lua_str("Reply"), "8", "nil", lua_int(REPLY_BIT))
        add("mesp.name", "string", lua_str("Function name"))
        ret = self.vs.add("mesp_ret", {int(k): str(v) for k, v in self.cat.mesp_ret.items()})
        add("mesp.ret", "uint32", lua_str("ret"), "base.DEC", ret)
        add("mesp.length", "uint32", lua_str("Length"), "base.DEC")
        types: dict[str, set[str]] = {}
        for fn in self.cat.mesp:
            for prm in (*fn.request, *fn.reply):
                types.setdefault(prm.name, set()).add(prm.type)
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
        if prm.type in ("string", "bytes"):  # ProtoField.string, ProtoField.bytes
            return self.fields.add(key, prm.type, lua_str(prm.name))
        raise SpecError(f"specs/mesp.yaml parameter {prm.name}: unknown type {prm.type}")


def value_table_int(values: dict[int, int]) -> str:
    """A Lua table ``{[key]=value}`` of integers, sorted by key."""
    return "{" + ", ".join(f"[{lua_int(k)}]={v}" for k, v in sorted(values.items())) + "}"


__all__ = ["MESP_PARAM_FIELD", "AppGenerator", "merge", "value_table", "value_table_int"]
