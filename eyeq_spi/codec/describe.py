"""Text views of the catalogue for ``eyeq-spi spec list`` and ``eyeq-spi spec show`` (in the
spirit of ``cantools dump``): offsets, sizes, types, ranges, enums and CRC coverage."""

from __future__ import annotations

from eyeq_spi.catalog.messages import Catalog, SwKey
from eyeq_spi.codec.bits import BitSignalCodec
from eyeq_spi.codec.layout import Layout, LayoutCache
from eyeq_spi.errors import SpecError


def _hz(value: float | None) -> str:
    return "-" if value is None else f"{value:g} Hz"


def spec_list(cat: Catalog, sw: SwKey) -> str:
    lc = LayoutCache(cat)
    out = [f"Messages (sizes for {sw}):"]
    for msg in cat.messages:
        exists = msg.exists_in(sw)
        size = "-"
        if exists:
            try:
                size = str(lc.get(msg.payload, sw).size)
            except SpecError:
                size = "?"
        ident = f"0x{msg.data_id:02X}"
        out.append(f"  {msg.protocol:5s} {ident:5s} {msg.name:34s} {msg.direction}  "
                   f"{_hz(msg.rate_hz):9s}"
                   f" {size:>6s} B  {','.join(msg.modes) or '-':14s}"
                   f"{'' if exists else '  (not in ' + sw + ')'}")
    out.append("MESP functions:")
    for function in cat.mesp:
        req = ", ".join(f"{p.name}:{p.type}" for p in function.request) or "-"
        rep = ", ".join(f"{p.name}:{p.type}" for p in function.reply) or "-"
        out.append(f"  0x{function.service:02X}/0x{function.function:02X} {function.name:28s} "
                   f"({req}) -> ret, {rep}")
    out.append("Init messages (bit tables):")
    for im in cat.init_messages.values():
        keys = ", ".join(im.variants) or "no table in the seed"
        out.append(f"  0x{im.id:02X} {im.name:28s} variants: {keys}")
    out.append("Structs:")
    for struct in cat.structs.values():
        out.append(f"  {struct.name:42s} §{struct.section or '?':8s} variants: "
                   f"{', '.join(struct.variants)}")
    out.append(f"Enums: {len(cat.enums)} ({sum(len(e.values) for e in cat.enums.values())} values)"
               f" — spec show ENUM_NAME lists one.")
    return "\n".join(out)


def _rng(lo: float | None, hi: float | None) -> str:
    if lo is None and hi is None:
        return ""
    return f"[{'' if lo is None else f'{lo:g}'}..{'' if hi is None else f'{hi:g}'}]"


def _layout_rows(lay: Layout, prefix: str, base: int, depth: int, rows: list[str]) -> None:
    for info in lay.fields:
        member = info.member
        name = prefix + info.name
        typ = info.type + (f"[{info.count}]" if info.count else "")
        bits = f" bits {info.bits[0]}-{info.bits[1]}" if info.bits else ""
        extra = " ".join(x for x in (member.units or "", _rng(member.min, member.max),
                                     f"enum {member.enum}" if member.enum else "") if x)
        rows.append(f"  {base + info.offset:6d} {info.size:6d}  {'  ' * depth}{typ:34s} "
                    f"{name}{bits}  {extra}".rstrip())
        child = lay.children.get(info.name)
        if child is not None and depth < 6:
            label = f"{name}[i]." if info.count else f"{name}."
            if info.count:
                rows.append(f"  {'':6s} {'':6s}  {'  ' * (depth + 1)}(stride {child.size} bytes, "
                            f"element 0 shown)")
            _layout_rows(child, label, base + info.offset, depth + 1, rows)


def show_layout(lay: Layout, header: str) -> str:
    rows = [header, f"  {'offset':>6s} {'size':>6s}  {'type':34s} name"]
    _layout_rows(lay, "", 0, 0, rows)
    if lay.crc_plan:
        rows.append("E2E (decision D5), inner structures first:")
        for plan in lay.crc_plan:
            where = plan.path or lay.name
            cov = ", ".join(f"{o}+{s}" for o, s in plan.ranges)
            ctr = "-" if plan.counter_offset is None else str(plan.counter_offset)
            rows.append(f"  {where}.{plan.field} @{plan.crc_offset}  counter @{ctr}  covers bytes "
                        f"{cov}")
    return "\n".join(rows)


def spec_show(cat: Catalog, name: str, sw: SwKey) -> str:
    lc = LayoutCache(cat)
    for msg in cat.messages:
        if msg.name == name:
            if not msg.exists_in(sw):
                raise SpecError(f"{name} does not exist in {sw} (since {msg.since})")
            lay = lc.get(msg.payload, sw)
            prefix = 4 if msg.protocol == "DASP" else 1
            head = (f"{msg.name}: {msg.protocol} 0x{msg.data_id:02X} {msg.direction} "
                    f"{_hz(msg.rate_hz)} "
                    f"modes {','.join(msg.modes) or '-'}; payload {lay.size} bytes after a "
                    f"{prefix}-byte header ({sw}, layout {lay.variant}); §{msg.section}")
            return show_layout(lay, head)
    if name in cat.structs:
        lay = lc.get(name, sw)
        struct = cat.structs[name]
        return show_layout(lay, f"{name}: {lay.size} bytes ({sw}, layout {lay.variant}); "
                                f"§{struct.section}; variants {', '.join(struct.variants)}")
    if name in cat.init_messages:
        codec = BitSignalCodec.for_message(name, sw, cat)
        im = codec.message
        rows = [f"{im.name}: init message 0x{im.id:02X}, {codec.length} bytes "
                f"({sw}, table {codec.variant.key}), raw = {im.rounding}((phys - offset)/factor)",
                f"  {'start':>5s} {'len':>4s} {'sign':4s} {'factor':>10s} {'offset':>8s} "
                f"{'range':22s} {'initial':>10s} name"]
        for sig in codec.variant.signals:
            kind = "f32" if sig.is_float else ("s" if sig.signed else "u")
            rows.append(f"  {sig.start:5d} {sig.length:4d} {kind:4s} {sig.factor:10g} "
                        f"{sig.offset:8g} {_rng(sig.min, sig.max):22s} {sig.initial:10g} "
                        f"{sig.name} {sig.units or ''}".rstrip())
        return "\n".join(rows)
    for function in cat.mesp:
        if function.name == name:
            rows = [f"{function.name}: MESP service 0x{function.service:02X} function "
                    f"0x{function.function:02X}",
                    "  request: header(5) "
                    + " ".join(f"{p.name}:{p.type}" for p in function.request),
                    "  reply:   header(5) ret:u32 " + " ".join(f"{p.name}:{p.type}"
                                                            for p in function.reply)]
            return "\n".join(rows)
    if name in cat.enums:
        enum = cat.enums[name]
        rows = [f"{name}: {enum.kind}, {len(enum.values)} entries"
                + ("" if enum.complete else " (incomplete: other values are not errors)")]
        for value, entry in sorted(enum.values.items()):
            more = " ".join(x for x in (entry.family or "", entry.semantic or "") if x)
            if entry.width > 1:  # a multi-bit field of a flag word
                more = ", ".join(f"{n}={label}"
                                 for n, label in sorted((entry.fields or {}).items()))
                last = value + entry.width - 1
                rows.append(f"  bits {value}-{last}  {entry.name}  {more}".rstrip())
                continue
            rows.append(f"  {'bit ' if enum.kind == 'flags' else ''}{value:5d}  {entry.name}  "
                        f"{more}".rstrip())
        return "\n".join(rows)
    raise SpecError(f"no message, struct, init message, MESP function or enum named {name!r}")
