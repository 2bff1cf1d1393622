"""How the scene's values reach a payload: :func:`put_values` of one struct's members (clamped as
:meth:`~eyeq_spi.sim.scene_layout.LayoutLeaf.clamp` says, generated writers into a packer's views),
writers bound once to a view (:func:`bound_puts`), constants written once per packer
(:func:`puts_once`), and the arrays of structs as rows (:func:`write_table`: generated row
writers) or, for the obstacles, numpy columns (split out of :mod:`eyeq_spi.sim.scene_layout`)."""

from __future__ import annotations

import functools
import struct
from collections.abc import Callable
from typing import Any

import numpy as np

from eyeq_spi.errors import LocalProtocolError
from eyeq_spi.sim.dasp_fast import BITS, NP_FMT, SCALAR, StructView
from eyeq_spi.sim.scene_layout import FArr, IArr, LayoutLeaf, LayoutNode, ObjectPlan


def _put(d: dict[str, Any], n: LayoutNode, key: str, x: float) -> None:
    leaf = n.members.get(key)
    if isinstance(leaf, LayoutLeaf) and key in d:
        d[key] = leaf.clamp(x)


def put_values(d: dict[str, Any], n: LayoutNode, vals: dict[str, float]) -> None:
    if isinstance(d, StructView):
        keys = tuple(vals)
        got = d.writers.get((id(n), keys))
        if got is None or got[0] is not n:
            got = d.writers[(id(n), keys)] = (n, _compile_puts(d, n, keys))
        if got[1] is not None:
            got[1](d.buf, d.shadow, vals)
            return
    for key, x in vals.items():
        _put(d, n, key, x)


def bound_puts(d: dict[str, Any], n: LayoutNode, keys: tuple[str, ...]
                ) -> Callable[[dict[str, float]], None]:
    """:func:`put_values` of values with ``keys`` into ``d`` as one callable: for a packer's view
    its generated writer bound to the view's buffer (views never change)."""
    if isinstance(d, StructView):
        fn = _compile_puts(d, n, keys)
        if fn is not None:
            return functools.partial(fn, d.buf, d.shadow)
    return functools.partial(put_values, d, n)


def puts_once(d: dict[str, Any], n: LayoutNode, key: str,
               make: Callable[[], dict[str, float]]) -> None:
    """:func:`put_values` of values that never change (``make()``, the same every call): a packer's
    view keeps its bytes from frame to frame and no other write touches these members, so they
    are written once after each reset; a dict gets them every time (the reference)."""
    if isinstance(d, StructView):
        k = (id(n), key)
        if k in d.done:
            return
        put_values(d, n, make())
        d.done.add(k)
        return
    put_values(d, n, make())


def _compile_puts(d: StructView, n: LayoutNode, keys: tuple[str, ...]
                  ) -> Callable[[bytearray, Any, dict[str, float]], None] | None:
    """:func:`put_values` into view ``d`` as generated code: per key the same clamp expression as
    :meth:`LayoutLeaf.clamp` and a ``pack_into`` at the member's offset from the layout (a bitfield
    read, masked and written back). None if a key names a struct or an array: the loop runs."""
    env: dict[str, Any] = {"LocalProtocolError": LocalProtocolError, "StructError": struct.error}
    body: list[str] = []
    for i, key in enumerate(keys):
        leaf = n.members.get(key)
        if not isinstance(leaf, LayoutLeaf) or key not in d:
            continue
        s = d.slots.get(key)
        if s is None or s.kind not in (SCALAR, BITS):
            return None
        env[f"K{i}"], env[f"L{i}"], env[f"H{i}"], env[f"S{i}"] = key, leaf.lo, leaf.hi, s.st
        o = d.base + s.offset
        body.append(f"x = float(min(max(v[K{i}], L{i}), H{i}))" if leaf.real
                    else f"x = int(min(max(round(v[K{i}]), L{i}), H{i}))")
        if s.kind == SCALAR:
            body.append(f"S{i}.pack_into(b, {o}, x)")
        else:
            keep = ((1 << (8 * s.st.size)) - 1) & ~(s.mask << s.lo)
            body += [f"if not isinstance(x, int) or not 0 <= x <= {s.mask}:",
                     f"    raise LocalProtocolError(f'{{K{i}}}: {{x!r}} does not fit "
                     f"{s.mask.bit_length()} bit(s)')",
                     f"S{i}.pack_into(b, {o}, S{i}.unpack_from(b, {o})[0] & {keep} | x << {s.lo})"]
        if d.shadow is not None:
            body.append(f"sh[K{i}] = x")
    src = ["def _w(b, sh, v):", "    try:"] + [f"        {line}" for line in body or ["pass"]]
    src += ["    except (StructError, TypeError) as exc:",
            "        raise LocalProtocolError(",
            f"            f'{d.layout.name}: cannot encode: {{exc}}') from None"]
    exec("\n".join(src), env)
    fn: Callable[[bytearray, Any, dict[str, float]], None] = env["_w"]
    return fn



def _write_rows(elems: list[dict[str, Any]], n: LayoutNode, rows: list[dict[str, float]],
                keys: tuple[str, ...]) -> None:
    """Rows into the first elements of an array of structs; ``keys`` of the rest zeroed."""
    for j, e in enumerate(elems):
        if j < len(rows):
            put_values(e, n, rows[j])
            continue
        for k in keys:
            leaf = n.members.get(k)
            if isinstance(leaf, LayoutLeaf) and k in e:
                e[k] = leaf.zero


_EXACT = 2.0**53  # ints below this survive float64 exactly
_MIN_NUMPY = 80  # values per table from which numpy clamps them (measured: numpy's ~17 µs)


def write_table(elems: list[dict[str, Any]], n: LayoutNode, rkeys: tuple[str, ...],
                 rows: list[tuple[float, ...]] | FArr, keys: tuple[str, ...]) -> None:
    """:func:`_write_rows` of rows given as tuples in the order of ``rkeys`` (or a float64
    matrix of such rows): a packer's views take them as one float64 matrix, clamped by numpy and
    packed by generated code (:func:`_compile_rows`); otherwise the rows become dicts."""
    if elems and isinstance(elems[0], StructView):
        ck = ("table", id(n), rkeys, keys, len(elems))
        got = elems[0].cache.get(ck)
        if got is None or got[0] is not n:
            got = elems[0].cache[ck] = (n, _compile_rows(elems, n, rkeys, keys))
        if got[1] is not None:
            lo, hi, ints, write, clamp_write = got[1]
            r = min(len(rows), len(elems))
            if r * len(rkeys) < _MIN_NUMPY:
                clamp_write(elems[0].buf, rows[:r])
                return
            m = np.array(rows[:r], dtype=np.float64).reshape(r, len(rkeys))
            if r and len(ints):
                x = m[:, ints]
                if not np.abs(x).max() < _EXACT:  # NaN compares False too
                    ints = None  # round() would raise, or float64 would not hold the int
                else:
                    m[:, ints] = np.rint(x)  # round(): half to even
            if ints is not None:
                m = np.where(lo > m, lo, m)  # min(max(x, lo), hi), NaN kept
                write(elems[0].buf, np.where(hi < m, hi, m).tolist())
                return
    if isinstance(rows, np.ndarray):
        rows = rows.tolist()
    _write_rows(elems, n, [dict(zip(rkeys, row, strict=True)) for row in rows], keys)


def _compile_rows(elems: list[StructView], n: LayoutNode, rkeys: tuple[str, ...],
                  keys: tuple[str, ...]) -> tuple[FArr, FArr, Any, Any, Any] | None:
    """:func:`write_table` into a packer's views: the bounds of the ``rkeys`` columns, the
    integer ones, and two generated writers that pack rows with one ``pack_into`` per run of
    adjacent members and zero ``keys`` of the elements past the rows by slices: one for rows
    numpy has clamped and rounded, one that clamps each value with :meth:`LayoutLeaf.clamp`'s
    expression. None (the loop runs) for elements not evenly spaced, a bitfield or struct
    member, a real into an integer or an integer range wider than its wire type."""
    first = elems[0]
    count = len(elems)
    stride = elems[1].base - first.base if count > 1 else first.layout.size
    if any(e.base != first.base + k * stride for k, e in enumerate(elems)):
        return None
    put: list[tuple[int, str, str]] = []  # (offset, struct code, expression)
    zero: list[tuple[int, int]] = []  # (offset, size) of the members zeroed past the rows
    lo, hi = np.full(len(rkeys), -np.inf), np.full(len(rkeys), np.inf)
    ints: list[int] = []
    clamped: list[str] = []  # the expressions of :meth:`LayoutLeaf.clamp`
    env: dict[str, Any] = {"LocalProtocolError": LocalProtocolError, "StructError": struct.error}
    for j, key in enumerate(rkeys + keys):
        leaf = n.members.get(key)
        if not isinstance(leaf, LayoutLeaf) or key not in first:
            continue
        s = first.slots.get(key)
        if s is None or s.kind != SCALAR or (leaf.real and not s.real):
            return None
        if not leaf.real and not s.real and not s.wire[0] <= leaf.lo <= leaf.hi <= s.wire[1]:
            return None
        if j >= len(rkeys):
            zero.append((s.offset, s.st.size))
            continue
        lo[j], hi[j] = leaf.lo, leaf.hi
        if not leaf.real:
            ints.append(j)
        put.append((s.offset, s.st.format[1:], f"r[{j}]" if leaf.real else f"int(r[{j}])"))
        clamped.append(f"float(min(max(r[{j}], L{j}), H{j}))" if leaf.real
                       else f"int(min(max(round(r[{j}]), L{j}), H{j}))")
        env[f"L{j}"], env[f"H{j}"] = leaf.lo, leaf.hi
    env["Z"] = _zero_spans(first.base, stride, count, zero)
    return (lo, hi, np.array(ints, dtype=np.intp), _rows_writer(first, stride, put, env),
            _rows_writer(first, stride, [(o, c, e) for (o, c, _), e in zip(put, clamped,
                                                                            strict=True)], env))


def _zero_spans(base: int, stride: int, count: int, zero: list[tuple[int, int]]
                ) -> list[list[tuple[int, int]]]:
    """Per number of rows, the byte ranges (merged) of the members zeroed past them."""
    spans = sorted((base + k * stride + off, size) for k in range(count) for off, size in zero)
    out = []
    for r in range(count + 1):
        merged: list[tuple[int, int]] = []
        for a, size in spans:
            if a < base + r * stride:
                continue
            if merged and merged[-1][1] == a:
                merged[-1] = (merged[-1][0], a + size)
            else:
                merged.append((a, a + size))
        out.append(merged)
    return out


def _rows_writer(first: StructView, stride: int, put: list[tuple[int, str, str]],
                 env: dict[str, Any]) -> Callable[[bytearray, list[Any]], None]:
    """Generated code packing rows, one ``pack_into`` per run of adjacent members."""
    env = dict(env)
    put = sorted(put)
    runs: list[tuple[int, str, list[str]]] = []
    for off, code, expr in put:
        last = runs[-1] if runs else None
        if last is not None and last[0] + struct.calcsize("<" + last[1]) == off:
            runs[-1] = (last[0], last[1] + code, [*last[2], expr])
        else:
            runs.append((off, code, [expr]))
    body = ["def _w(b, rows):", "    try:", f"        o = {first.base}", "        for r in rows:"]
    for k, (off, code, exprs) in enumerate(runs):
        env[f"S{k}"] = struct.Struct("<" + code)
        body.append(f"            S{k}.pack_into(b, o + {off}, {', '.join(exprs)})")
    body += [f"            o += {stride}", "        for a, e in Z[len(rows)]:",
             "            b[a:e] = bytes(e - a)",
             "    except (StructError, TypeError, OverflowError) as exc:",
             "        raise LocalProtocolError(",
             f"            f'{first.layout.name}: cannot encode: {{exc}}') from None"]
    exec("\n".join(body), env)
    fn: Callable[[bytearray, list[Any]], None] = env.pop("_w")
    return fn


def write_objects_packed(objs: list[Any], plan: ObjectPlan, fl: FArr, il: IArr, n: int) -> bool:
    """The object loop of ``Scene._fill_obstacles`` into a packer's views: the same clamped
    arrays, cast per wire type into one byte array and scattered into the payload bytes at once
    (slots past ``n`` get 0). False (nothing written) when the loop must run."""
    first = objs[0]
    ck = ("objs", id(plan), len(objs))
    got = first.cache.get(ck)
    if got is None or got[0] is not plan:
        got = first.cache[ck] = (plan, _objects_plan(objs, plan))
    p = got[1]
    if p is None:
        return False
    u8, groups, check, bitgroups, raw, everywhere = p
    rows, lo, hi = check
    if n and len(rows):  # one range check for every integer column (wire type or bit width)
        x = il[rows]
        if (x < lo).any() or (x > hi).any():
            return False  # the encoder would refuse it: let the loop raise
    count = len(objs)
    for real, rows, v in groups:
        v[:, :n] = fl[rows] if real else il[rows]
        if n < count:
            v[:, n:] = 0
    for brows, shift, starts, base, v in bitgroups:
        # a container holds the bits the objects do not write as they are (D2 unused bits set)
        if n < count:
            v[:, n:] = base[:, n:]
        if n:
            v[:, :n] = base[:, :n] | np.bitwise_or.reduceat(il[brows] << shift, starts, axis=0)
    u8[everywhere] = raw  # every group's bytes in one scatter
    return True


def _objects_plan(objs: list[StructView], plan: ObjectPlan) -> tuple[Any, ...] | None:
    """Per (wire type, source) the rows of the column arrays, the payload byte indices they go
    to and a reused array; the integer rows' bounds; per container type the bit columns."""
    first = objs[0]
    count = len(objs)
    stride = objs[1].base - first.base if count > 1 else first.layout.size
    if any(obj.base != first.base + k * stride for k, obj in enumerate(objs)):
        return None
    slots = _object_slots(first, plan)
    if slots is None:
        return None
    by_type, bits, check = slots
    u8 = np.frombuffer(first.buf, dtype=np.uint8)
    # each group's values live in one byte array (widest types first: aligned), scattered into
    # the payload at once by the concatenation of the groups' indices
    order = sorted(by_type.items(), key=lambda kv: -np.dtype(NP_FMT[kv[0][0]]).itemsize)
    groups = []
    for (typ, real), cols in order:
        dt, idx = _byte_index(first, stride, count, typ, [rel for _, rel in cols])
        groups.append((real, np.array([row for row, _ in cols]), idx,
                       np.zeros((len(cols), count), dtype=dt)))
    bitgroups = _bit_containers(first, stride, count, bits)
    bounds = (np.array([row for row, _, _ in check], dtype=np.intp),
              np.array([lo for _, lo, _ in check], dtype=np.float64)[:, None],
              np.array([hi for _, _, hi in check], dtype=np.float64)[:, None])
    arrays = [g[3] for g in groups] + [b[5] for b in bitgroups]
    raw = np.zeros(sum(a.nbytes for a in arrays), dtype=np.uint8)
    views, at = [], 0
    for array in arrays:
        views.append(raw[at:at + array.nbytes].view(array.dtype).reshape(array.shape))
        at += array.nbytes
    for number, bitgroup in enumerate(bitgroups):  # the containers as the payload holds them
        views[len(groups) + number][:] = bitgroup[3]
    everywhere = np.concatenate([g[2] for g in groups] + [b[4] for b in bitgroups])
    return (u8, [(g[0], g[1], v) for g, v in zip(groups, views, strict=False)], bounds,
            [(*b[:4], v) for b, v in zip(bitgroups, views[len(groups):], strict=True)], raw,
            everywhere)


_Bits = dict[int, tuple[str, list[tuple[int, int, int]]]]


def _object_slots(first: StructView, plan: ObjectPlan
                  ) -> tuple[dict[tuple[str, bool], list[tuple[int, int]]], _Bits,
                             list[tuple[int, float, float]]] | None:
    """Where the first object puts each column row: per (wire type, real) the rows and their
    offsets from the first object, per bit container offset its type and bit fields, and the
    bounds to check the integer rows against. None when a row has no plain slot."""
    by_type: dict[tuple[str, bool], list[tuple[int, int]]] = {}
    bits: _Bits = {}
    check: list[tuple[int, float, float]] = []
    for path, items in plan.groups:
        probe: Any = first
        for step in path:
            ok = (isinstance(probe, StructView) and isinstance(step, str) and step in probe) or (
                isinstance(probe, list) and isinstance(step, int) and step < len(probe))
            probe = probe[step] if ok else None
        if not isinstance(probe, StructView):
            continue
        for key, real, row in items:
            if key not in probe:
                continue
            slot = probe.slots.get(key)
            if slot is None or slot.kind not in (SCALAR, BITS) or (real and not slot.real):
                return None
            rel = probe.base - first.base + slot.offset
            if slot.kind == BITS:
                bits.setdefault(rel, (slot.type, []))[1].append((row, slot.lo, slot.mask))
                check.append((row, 0, slot.mask))
                continue
            by_type.setdefault((slot.type, real), []).append((row, rel))
            if not real and not slot.real:
                check.append((row, *slot.wire))
    return by_type, bits, check


def _byte_index(first: StructView, stride: int, count: int, typ: str, rels: list[int]
                ) -> tuple[np.dtype[Any], Any]:
    """The dtype of ``typ`` and the payload index of every (column, object, byte), in the
    order of ``values.view(uint8).ravel()``."""
    dt = np.dtype(NP_FMT[typ])
    offsets = np.array(rels)
    return dt, (first.base + offsets[:, None, None] + stride * np.arange(count)[None, :, None]
                + np.arange(dt.itemsize)[None, None, :]).ravel()


def _bit_containers(first: StructView, stride: int, count: int, bits: _Bits) -> list[Any]:
    """Per container type: the rows, shifts and starts to OR the bit columns together, each
    container's bits that the objects do not write, its byte index and a reused array."""
    bitgroups = []
    for typ in sorted({typ for typ, _ in bits.values()}):
        rels = [rel for rel, (rel_type, _) in bits.items() if rel_type == typ]
        dt, idx = _byte_index(first, stride, count, typ, rels)
        brows: list[int] = []
        shift: list[int] = []
        starts: list[int] = []
        base = np.zeros((len(rels), count), dtype=dt)
        for number, rel in enumerate(rels):
            starts.append(len(brows))
            used = 0
            for row, lo, mask in bits[rel][1]:
                brows.append(row)
                shift.append(lo)
                used |= mask << lo
            for obj in range(count):  # the container as it stands, less the bits written here
                off = first.base + rel + obj * stride
                base[number, obj] = int.from_bytes(first.buf[off:off + dt.itemsize],
                                                   "little") & ~used
        bitgroups.append((np.array(brows), np.array(shift)[:, None], np.array(starts), base,
                          idx, np.zeros_like(base)))
    return bitgroups
