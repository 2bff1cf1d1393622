"""Text views of the catalogue for ``eyeq-spi spec list`` and ``eyeq-spi spec show`` (in the
spirit of ``cantools dump``): offsets, sizes, types, ranges, enums and CRC coverage."""

from __future__ import annotations

from eyeq_spi.catalog.messages import Catalog, SwKey
from eyeq_spi.codec.bits import BitSignalCodec
from eyeq_spi.codec.layout import Layout, LayoutCache
from eyeq_spi.errors import SpecError


def _hz(v: float | None) -> str:
    return "-" if v is None else f"{v:g} Hz"


def spec_list(cat: Catalog, sw: SwKey) -> str:
    lc = LayoutCache(cat)
    out = [f"Messages (sizes for {sw}):"]
    for m in cat.messages:
        exists = m.exists_in(sw)
        size = "-"
        if exists:
            try:
                size = str(lc.get(m.payload, sw).size)
            except SpecError:
                size = "?"
        ident = f"0x{m.data_id:02X}"
        out.append(f"  {m.protocol:5s} {ident:5s} {m.name:34s} {m.direction}  {_hz(m.rate_hz):9s}"
                   f" {size:>6s} B  {','.join(m.modes) or '-':14s}"
                   f"{'' if exists else '  (not in ' + sw + ')'}")
    out.append("MESP functions:")
    for f in cat.mesp:
        req = ", ".join(f"{p.name}:{p.type}" for p in f.request) or "-"
        rep = ", ".join(f"{p.name}:{p.type}" for p in f.reply) or "-"
        out.append(f"  0x{f.service:02X}/0x{f.function:02X} {f.name:28s} ({req}) -> ret, {rep}")
    out.append("Init messages (bit tables):")
    for im in cat.init_messages.values():
        keys = ", ".join(im.variants) or "no table in the seed"
        out.append(f"  0x{im.id:02X} {im.name:28s} variants: {keys}")
    out.append("Structs:")
    for s in cat.structs.values():
        out.append(f"  {s.name:42s} §{s.section or '?':8s} variants: {', '.join(s.variants)}")
    out.append(f"Enums: {len(cat.enums)} ({sum(len(e.values) for e in cat.enums.values())} values)"
               f" — spec show ENUM_NAME lists one.")
    return "\n".join(out)


def _rng(lo: float | None, hi: float | None) -> str:
    if lo is None and hi is None:
        return ""
    return f"[{'' if lo is None else f'{lo:g}'}..{'' if hi is None else f'{hi:g}'}]"


def _layout_rows(lay: Layout, prefix: str, base: int, depth: int, rows: list[str]) -> None:
    for f in lay.fields:
        m = f.member
        name = prefix + f.name
        typ = f.type + (f"[{f.count}]" if f.count else "")
        bits = f" bits {f.bits[0]}-{f.bits[1]}" if f.bits else ""
        extra = " ".join(x for x in (m.units or "", _rng(m.min, m.max),
                                     f"enum {m.enum}" if m.enum else "") if x)
        rows.append(f"  {base + f.offset:6d} {f.size:6d}  {'  ' * depth}{typ:34s} "
                    f"{name}{bits}  {extra}".rstrip())
        child = lay.children.get(f.name)
        if child is not None and depth < 6:
            label = f"{name}[i]." if f.count else f"{name}."
            if f.count:
                rows.append(f"  {'':6s} {'':6s}  {'  ' * (depth + 1)}(stride {child.size} bytes, "
                            f"element 0 shown)")
            _layout_rows(child, label, base + f.offset, depth + 1, rows)


def show_layout(lay: Layout, header: str) -> str:
    rows = [header, f"  {'offset':>6s} {'size':>6s}  {'type':34s} name"]
    _layout_rows(lay, "", 0, 0, rows)
    if lay.crc_plan:
        rows.append("E2E (decision D5), inner structures first:")
        for p in lay.crc_plan:
            where = p.path or lay.name
            cov = ", ".join(f"{o}+{s}" for o, s in p.ranges)
            ctr = "-" if p.counter_offset is None else str(p.counter_offset)
            rows.append(f"  {where}.{p.field} @{p.crc_offset}  counter @{ctr}  covers bytes {cov}")
    return "\n".join(rows)


def spec_show(cat: Catalog, name: str, sw: SwKey) -> str:
    lc = LayoutCache(cat)
    for m in cat.messages:
        if m.name == name:
            if not m.exists_in(sw):
                raise SpecError(f"{name} does not exist in {sw} (since {m.since})")
            lay = lc.get(m.payload, sw)
            prefix = 4 if m.protocol == "DASP" else 1
            head = (f"{m.name}: {m.protocol} 0x{m.data_id:02X} {m.direction} {_hz(m.rate_hz)} "
                    f"modes {','.join(m.modes) or '-'}; payload {lay.size} bytes after a "
                    f"{prefix}-byte header ({sw}, layout {lay.variant}); §{m.section}")
            return show_layout(lay, head)
    if name in cat.structs:
        lay = lc.get(name, sw)
        s = cat.structs[name]
        return show_layout(lay, f"{name}: {lay.size} bytes ({sw}, layout {lay.variant}); "
                                f"§{s.section}; variants {', '.join(s.variants)}")
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
    for f in cat.mesp:
        if f.name == name:
            rows = [f"{f.name}: MESP service 0x{f.service:02X} function 0x{f.function:02X}",
                    "  request: header(5) " + " ".join(f"{p.name}:{p.type}" for p in f.request),
                    "  reply:   header(5) ret:u32 " + " ".join(f"{p.name}:{p.type}"
                                                            for p in f.reply)]
            return "\n".join(rows)
    if name in cat.enums:
        e = cat.enums[name]
        rows = [f"{name}: {e.kind}, {len(e.values)} entries"
                + ("" if e.complete else " (incomplete: other values are not errors)")]
        for k, v in sorted(e.values.items()):
            more = " ".join(x for x in (v.family or "", v.semantic or "") if x)
            if v.width > 1:  # a multi-bit field of a flag word
                more = ", ".join(f"{n}={label}" for n, label in sorted((v.fields or {}).items()))
                rows.append(f"  bits {k}-{k + v.width - 1}  {v.name}  {more}".rstrip())
                continue
            rows.append(f"  {'bit ' if e.kind == 'flags' else ''}{k:5d}  {v.name}  {more}".rstrip())
        return "\n".join(rows)
    raise SpecError(f"no message, struct, init message, MESP function or enum named {name!r}")
