"""How the scene's values reach a payload: :func:`put_values` of one struct's members (clamped
as :meth:`~eyeq_spi.sim.scene_layout.LayoutLeaf.clamp` says), constants written once per packer
(:func:`puts_once`), and arrays of structs as rows (:func:`write_table`) or, for the obstacles,
numpy columns."""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import numpy as np

from eyeq_spi.errors import LocalProtocolError
from eyeq_spi.sim.dasp_fast import BITS, NP_FMT, SCALAR, StructView
from eyeq_spi.sim.scene_layout import FArr, IArr, LayoutLeaf, LayoutNode, ObjectPlan, member_at


def _put(target: dict[str, Any], node: LayoutNode, key: str, value: float) -> None:
    leaf = node.members.get(key)
    if isinstance(leaf, LayoutLeaf) and key in target:
        target[key] = leaf.clamp(value)


def put_values(target: dict[str, Any], node: LayoutNode, vals: dict[str, float]) -> None:
    for key, value in vals.items():
        _put(target, node, key, value)


def puts_once(target: dict[str, Any], node: LayoutNode, key: str,
              make: Callable[[], dict[str, float]]) -> None:
    """:func:`put_values` of values that never change: a packer's view keeps its bytes from
    frame to frame, so they are written once after each reset; a dict gets them every time."""
    done = target.done if isinstance(target, StructView) else None
    if done is not None and (id(node), key) in done:
        return
    put_values(target, node, make())
    if done is not None:
        done.add((id(node), key))


def write_table(elems: list[dict[str, Any]], node: LayoutNode, keys: tuple[str, ...],
                rows: list[tuple[float, ...]]) -> None:
    """Rows, tuples in the order of ``keys``, into the first elements of an array of structs;
    ``keys`` of the rest zeroed. Into a packer's views by a generated writer
    (:func:`_compile_rows`)."""
    if elems and isinstance(elems[0], StructView):
        cache, cache_key = elems[0].cache, ("table", node, keys, len(elems))
        if cache_key not in cache:
            cache[cache_key] = _compile_rows(elems, node, keys)
        if cache[cache_key] is not None:
            cache[cache_key](elems[0].buf, rows[:len(elems)])
            return
    for index, elem in enumerate(elems):
        if index < len(rows):
            put_values(elem, node, dict(zip(keys, rows[index], strict=True)))
            continue
        for key in keys:
            leaf = node.members.get(key)
            if isinstance(leaf, LayoutLeaf) and key in elem:
                elem[key] = 0.0 if leaf.real else 0


def _compile_rows(elems: list[StructView], node: LayoutNode, keys: tuple[str, ...]
                  ) -> Callable[[bytearray, Any], None] | None:
    """:func:`write_table` into a packer's views: a generated writer that clamps each value as
    :meth:`LayoutLeaf.clamp` does, packs rows with one ``pack_into`` per run of adjacent members
    and zeroes the members past the rows; None (the loop runs) when the layout does not allow
    it."""
    first = elems[0]
    count = len(elems)
    stride = elems[1].base - first.base if count > 1 else first.layout.size
    if any(e.base != first.base + k * stride for k, e in enumerate(elems)):
        return None
    put: list[tuple[int, str, str]] = []  # (offset, struct code, clamped expression)
    zero: list[tuple[int, int]] = []  # (offset, size) of the members zeroed past the rows
    env: dict[str, Any] = {"LocalProtocolError": LocalProtocolError, "StructError": struct.error}
    for column, key in enumerate(keys):
        leaf = node.members.get(key)
        if not isinstance(leaf, LayoutLeaf) or key not in first:
            continue
        slot = first.slots.get(key)
        if slot is None or slot.kind != SCALAR or (leaf.real and not slot.real):
            return None
        if (not leaf.real and not slot.real
                and not slot.wire[0] <= leaf.lo <= leaf.hi <= slot.wire[1]):
            return None
        zero.append((slot.offset, slot.st.size))
        put.append((slot.offset, slot.st.format[1:],
                    f"float(min(max(r[{column}], L{column}), H{column}))" if leaf.real
                    else f"int(min(max(round(r[{column}]), L{column}), H{column}))"))
        env[f"L{column}"], env[f"H{column}"] = leaf.lo, leaf.hi
    env["Z"] = _zero_spans(first.base, stride, count, zero)
    return _rows_writer(first, stride, put, env)


def _zero_spans(base: int, stride: int, count: int, zero: list[tuple[int, int]]
                ) -> list[list[tuple[int, int]]]:
    """Per number of rows, the byte ranges (merged) of the members zeroed past them."""
    spans = sorted((base + k * stride + off, size) for k in range(count) for off, size in zero)
    out = []
    for rows in range(count + 1):
        merged: list[tuple[int, int]] = []
        for start, size in spans:
            if start < base + rows * stride:
                continue
            if merged and merged[-1][1] == start:
                merged[-1] = (merged[-1][0], start + size)
            else:
                merged.append((start, start + size))
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
    for run, (off, code, exprs) in enumerate(runs):
        env[f"S{run}"] = struct.Struct("<" + code)
        body.append(f"            S{run}.pack_into(b, o + {off}, {', '.join(exprs)})")
    body += [f"            o += {stride}", "        for a, e in Z[len(rows)]:",
             "            b[a:e] = bytes(e - a)",
             "    except (StructError, TypeError, OverflowError) as exc:",
             "        raise LocalProtocolError(",
             f"            f'{first.layout.name}: cannot encode: {{exc}}') from None"]
    exec("\n".join(body), env)
    fn: Callable[[bytearray, list[Any]], None] = env.pop("_w")
    return fn


def write_objects_packed(objs: list[Any], plan: ObjectPlan, fl: FArr, il: IArr,
                         filled: int) -> bool:
    """The object loop of ``Scene._fill_obstacles`` into a packer's views: the same clamped
    arrays, cast per wire type and scattered into the payload bytes (slots past ``filled`` get
    0). False (nothing written) when the loop must run."""
    first = objs[0]
    key = ("objs", plan, len(objs))
    if key not in first.cache:
        first.cache[key] = _objects_plan(objs, plan)
    compiled = first.cache[key]
    if compiled is None:
        return False
    u8, groups, check, bitgroups = compiled
    rows, lo, hi = check
    if filled and len(rows):  # one range check for every integer column (wire type or bit width)
        int_rows = il[rows]
        if (int_rows < lo).any() or (int_rows > hi).any():
            return False  # the encoder would refuse it: let the loop raise
    count = len(objs)
    for real, rows, where, scratch in groups:
        scratch[:, :filled] = fl[rows] if real else il[rows]
        if filled < count:
            scratch[:, filled:] = 0
        u8[where] = scratch.view(np.uint8).ravel()
    for brows, shift, starts, base, where, scratch in bitgroups:
        # a container holds the bits the objects do not write as they are (D2 unused bits set)
        if filled < count:
            scratch[:, filled:] = base[:, filled:]
        if filled:
            bits = np.bitwise_or.reduceat(il[brows] << shift, starts, axis=0)
            scratch[:, :filled] = base[:, :filled] | bits
        u8[where] = scratch.view(np.uint8).ravel()
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
    groups = []
    for (typ, real), cols in by_type.items():
        dt, idx = _byte_index(first, stride, count, typ, [rel for _, rel in cols])
        groups.append((real, np.array([row for row, _ in cols]), idx,
                       np.zeros((len(cols), count), dtype=dt)))
    bitgroups = _bit_containers(first, stride, count, bits)
    bounds = (np.array([row for row, _, _ in check], dtype=np.intp),
              np.array([lo for _, lo, _ in check], dtype=np.float64)[:, None],
              np.array([hi for _, _, hi in check], dtype=np.float64)[:, None])
    return u8, groups, bounds, bitgroups


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
        probe = member_at(first, path)
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
