"""Many messages of one layout at once: numpy columns, E2E and enum checks over a whole group.

A :class:`VecLayout` is built once per :class:`~eyeq_spi.codec.layout.Layout` from its
``FieldInfo`` lists: a structured dtype with one field per primitive leaf (named as
``dissect --csv`` flattens them, bitfields cut out with the codec's shifts, D2); E2E (D5) over
all rows with a table-driven CRC-16 (two bytes per numpy step; ``binascii.crc_hqx`` row by row
for long plans with few rows), counters against the previous row and the ``E2EState``; and the
dissector's enum checks. ``verify`` and ``enum_errors`` give, row by row, the same strings as
:func:`eyeq_spi.codec.e2e.verify` and the reference dissector, and update the state the same way."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from eyeq_spi.codec.e2e import E2EState, counter_key, crc_label, plan_crc
from eyeq_spi.crc import crc16

if TYPE_CHECKING:
    from eyeq_spi.catalog.messages import Catalog
    from eyeq_spi.codec.layout import CrcPlan, Layout

NP_TYPE = {"uint8": "u1", "uint16": "<u2", "uint32": "<u4", "uint64": "<u8", "int8": "i1",
           "int16": "<i2", "int32": "<i4", "int64": "<i8", "real32": "<f4", "real64": "<f8",
           "bool": "u1"}
INT_TYPES = {"uint8", "uint16", "uint32", "uint64", "int8", "int16", "int32", "int64", "bool"}
MAX_ENUM_ERRORS = 10  # the reference dissector keeps the first ten (engine._enum_errors)


def crc_word_tables(crc: Callable[[bytes], int]) -> tuple[np.ndarray, np.ndarray]:
    """T1[b]: the register after byte b from register 0; T2[w]: after the big-endian word w
    from 0, for a CRC-16 function ``crc`` of the form CRC-16/CCITT-FALSE has (not reflected,
    xorout 0, so linear in the register). ``crc`` starts at ``init``; its two big-endian bytes
    bring the register to 0, so ``crc(init_bytes + bytes([b]))`` is T1[b]; T2 is composed from
    T1. Built once per function (the frame CRC of the dissector's fast path, L3, and the E2E
    CRCs here are the same ``crc16``); a caller with another function checks the tables."""
    got = _WORD_TABLES.get(crc)
    if got is None:
        lead = crc(b"").to_bytes(2, "big")
        t1 = np.array([crc(lead + bytes([b])) & 0xFFFF for b in range(256)], np.uint32)
        word = np.arange(65536, dtype=np.uint32)
        r1 = t1[word >> 8]
        t2 = ((r1 << 8) & 0xFFFF) ^ t1[(r1 >> 8) ^ (word & 0xFF)]
        got = _WORD_TABLES[crc] = (t1.astype(np.uint16), t2.astype(np.uint16))
    return got


_WORD_TABLES: dict[Callable[[bytes], int], tuple[np.ndarray, np.ndarray]] = {}


def crc_rows(data: np.ndarray, init: int = 0xFFFF) -> np.ndarray:
    """CRC-16 (``crc16``'s variant) of every row of the uint8 array ``g`` (n, L)."""
    t1, t2 = crc_word_tables(crc16)
    count, length = data.shape
    crc = np.full(count, init, np.uint16)
    half = length // 2
    if half:
        wide = data[:, : 2 * half].astype(np.uint16)
        words = np.ascontiguousarray(((wide[:, 0::2] << 8) | wide[:, 1::2]).T)
        for step in range(half):
            crc = t2[crc ^ words[step]]
    if length % 2:
        crc = ((crc << 8) & 0xFFFF).astype(np.uint16) ^ t1[(crc >> 8) ^ data[:, -1]]
    return crc


class _Leaf(NamedTuple):  # a tuple: a layout has thousands, built at every start
    name: str  # flattened path
    field: str  # structured dtype field (the container for bitfields)
    shift: int
    mask: int | None  # None: the whole field
    type: str


@dataclass(frozen=True)
class _Plan:
    """An E2E check of the layout as byte offsets (gathered for all rows at once)."""

    index: int
    source: CrcPlan
    idx: np.ndarray  # covered byte offsets, in order
    key: tuple[str, str]
    crc_text: str
    jump_text: str


class _EnumLeaf(NamedTuple):
    leaf: _Leaf
    label: str  # "<path>.<member>" after the message name
    values: np.ndarray
    enum: str
    table: np.ndarray | None  # bool per possible value (fields of 16 bits or fewer), else isin

    def bad(self, col: np.ndarray) -> np.ndarray:
        if self.table is not None:
            return self.table[col]  # type: ignore[no-any-return]
        return ~np.isin(col, self.values)


_ENUM_TABLES: dict[tuple[tuple[int, ...], int, bool], tuple[np.ndarray, np.ndarray | None]] = {}


def _enum_leaf(leaf: _Leaf, label: str, values: tuple[int, ...], enum: str) -> _EnumLeaf:
    """The check of one enum member (``values`` sorted); its value array and table are shared by
    every member with the same values and width (built once: a layout has hundreds of such
    members)."""
    bits = (leaf.mask.bit_length() if leaf.mask is not None
            else 8 * np.dtype(NP_TYPE[leaf.type]).itemsize)
    key = (values, bits, leaf.type.startswith(("uint", "bool")))
    hit = _ENUM_TABLES.get(key)
    if hit is None:
        arr = np.array(key[0])
        table = None
        if bits <= 16 and key[2]:
            table = np.ones(1 << bits, bool)
            ok = arr[(arr >= 0) & (arr < (1 << bits))]
            table[ok] = False
        hit = _ENUM_TABLES[key] = (arr, table)
    return _EnumLeaf(leaf, label, hit[0], enum, hit[1])


_new_leaf = tuple.__new__  # a _Leaf without the Python call of its __new__: thousands a start

_FieldRow = tuple[str, int, int, str, "int | None", "tuple[int, int] | None", "Layout | None",
                  "tuple[str, tuple[int, ...]] | None"]
_FIELDS: dict[tuple[int, bool], tuple[Layout, list[_FieldRow]]] = {}


def _fields(lay: Layout, cat: Catalog, enums: bool) -> list[_FieldRow]:
    """What :meth:`VecLayout._walk` reads of each field of ``lay``, once per layout: name,
    offset, size, type, count, bits, child layout and the enum to check with its sorted values
    (None: no check). A struct array walks its element's layout once per element."""
    hit = _FIELDS.get((id(lay), enums))
    if hit is not None and hit[0] is lay:
        return hit[1]
    rows: list[_FieldRow] = []
    for field in lay.fields:
        enum = cat.enums.get(field.member.enum or "")
        check = (enums and enum is not None and enum.kind != "flags" and enum.complete
                 and not field.count and field.type in INT_TYPES)
        rows.append((field.name, field.offset, field.size, field.type, field.count, field.bits,
                     lay.children.get(field.name),
                     (enum.name, tuple(sorted(enum.values)))
                     if check and enum is not None else None))
    _FIELDS[(id(lay), enums)] = (lay, rows)
    return rows


class VecLayout:
    """The vectorised decoder of one layout."""

    def __init__(self, lay: Layout, cat: Catalog) -> None:
        self.layout = lay
        self.size = lay.size
        names: list[str] = []
        formats: list[str] = []
        offsets: list[int] = []
        self.leaves: list[_Leaf] = []
        self.enums: list[_EnumLeaf] = []
        self._walk(lay, cat, "", 0, names, formats, offsets, True)
        self.dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets,
                               "itemsize": lay.size})
        self.plans = [
            _Plan(i, p, np.array([o + k for o, s in p.ranges for k in range(s)], np.intp),
                  counter_key(lay, p), f"E2E CRC mismatch in {crc_label(lay, p)}: {p.field}=0x",
                  f"E2E counter jump in {crc_label(lay, p)}: expected ")
            for i, p in enumerate(lay.crc_plan)
        ]

    def _walk(self, lay: Layout, cat: Catalog, prefix: str, base: int, names: list[str],
              formats: list[str], offsets: list[int], enums: bool) -> None:
        seen: set[int] = set()
        leaves = self.leaves
        for name, off, size, typ, count, bits, child, enum_check in _fields(lay, cat, enums):
            path = f"{prefix}.{name}" if prefix else name
            if bits is not None:
                cont = f"{prefix}#bits@{off}"
                if off not in seen:
                    seen.add(off)
                    names.append(cont)
                    formats.append(NP_TYPE[typ])
                    offsets.append(base + off)
                lo, hi = bits
                leaf = _new_leaf(_Leaf, (path, cont, lo, (1 << (hi - lo + 1)) - 1, typ))
                leaves.append(leaf)
                if enum_check is not None:
                    self.enums.append(_enum_leaf(leaf, path, enum_check[1], enum_check[0]))
                continue
            if child is not None:
                for element in range(count or 1):
                    sub = f"{path}[{element}]" if count else path
                    self._walk(child, cat, sub, base + off + element * child.size, names,
                               formats, offsets, enums)
                continue
            at = base + off
            if count:  # never an enum check (scalars only)
                width = size // count
                items = [f"{path}[{i}]" for i in range(count)]
                names += items
                formats += [NP_TYPE[typ]] * count
                offsets += [at + i * width for i in range(count)]
                leaves += [_new_leaf(_Leaf, (n, n, 0, None, typ)) for n in items]
                continue
            names.append(path)
            formats.append(NP_TYPE[typ])
            offsets.append(at)
            leaf = _new_leaf(_Leaf, (path, path, 0, None, typ))
            leaves.append(leaf)
            if enum_check is not None:
                self.enums.append(_enum_leaf(leaf, path, enum_check[1], enum_check[0]))

    # -- values ----------------------------------------------------------------------------
    def records(self, payloads: np.ndarray) -> np.ndarray:
        """The payloads ``(n, size)`` uint8 as structured records (a view, no copy)."""
        arr = np.ascontiguousarray(payloads)
        return arr.view(self.dtype).reshape(len(arr))

    def column(self, rec: np.ndarray, leaf: _Leaf) -> np.ndarray:
        col = rec[leaf.field]
        if leaf.mask is None:
            return col
        return (col >> leaf.shift) & leaf.mask

    def columns(self, payloads: np.ndarray) -> dict[str, np.ndarray]:
        """Every leaf as a column, flattened names, in the order of ``flatten(fields)``."""
        rec = self.records(payloads)
        return {leaf.name: self.column(rec, leaf) for leaf in self.leaves}

    # -- E2E -------------------------------------------------------------------------------
    def crc_ok(self, payloads: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(got, computed) CRC fields as (n, plans) uint16 arrays and got == computed."""
        row_count = len(payloads)
        plan_count = len(self.plans)
        got = np.zeros((row_count, plan_count), np.uint16)
        want = np.zeros((row_count, plan_count), np.uint16)
        by_len: dict[int, list[_Plan]] = {}
        for plan in self.plans:
            crc_at = plan.source.crc_offset
            got[:, plan.index] = payloads[:, crc_at].astype(np.uint16) | (
                payloads[:, crc_at + 1].astype(np.uint16) << 8)
            by_len.setdefault(len(plan.idx), []).append(plan)
        for length, plans in by_len.items():
            rows = row_count * len(plans)
            # numpy: ~length/2 steps of fixed cost; crc_hqx: a call per row and range in C
            if length // 2 * 1.5 > rows * (0.3 + length / 1500):
                for plan in plans:
                    want[:, plan.index] = _crc_loop(payloads, plan.source)
                continue
            idx = np.stack([plan.idx for plan in plans])  # (P, L)
            gathered = payloads[:, idx].reshape(rows, length)
            crcs = crc_rows(gathered).reshape(row_count, len(plans))
            for position, plan in enumerate(plans):
                want[:, plan.index] = crcs[:, position]
        return got, want, got == want

    def verify(self, payloads: np.ndarray, state: E2EState | None) -> list[list[str]]:
        """Per row, what :func:`eyeq_spi.codec.e2e.verify` reports for it when the rows are
        verified in order with ``state``; ``state`` ends as it would."""
        row_count = len(payloads)
        errs: list[list[str]] = [[] for _ in range(row_count)]
        if not self.plans or not row_count:
            return errs
        got, want, ok = self.crc_ok(payloads)
        bad_any = ~ok.all(axis=1)
        jumps: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        if state is not None:
            state.crc_errors += int((~ok).sum())
            for plan in self.plans:
                offset, size = plan.source.counter_offset, plan.source.counter_size
                if offset is None:
                    continue
                counters = np.zeros(row_count, np.int64)
                for byte in range(size):
                    counters |= payloads[:, offset + byte].astype(np.int64) << (8 * byte)
                modulo = 1 << (8 * size)
                last = state.seen.get(plan.key)
                prev = np.empty(row_count, np.int64)
                prev[0] = -1 if last is None else last
                prev[1:] = counters[:-1]
                expected = (prev + 1) % modulo
                jump = (prev >= 0) & (counters != expected)
                state.seen[plan.key] = int(counters[-1])
                if jump.any():
                    state.counter_errors += int(jump.sum())
                    bad_any |= jump
                    jumps[plan.index] = (jump, np.stack([expected, counters], axis=1))
        for row in np.flatnonzero(bad_any).tolist():
            out = errs[row]
            for plan in self.plans:
                if not ok[row, plan.index]:
                    out.append(f"{plan.crc_text}{int(got[row, plan.index]):04X}, computed "
                               f"0x{int(want[row, plan.index]):04X}")
                jump_entry = jumps.get(plan.index)
                if jump_entry is not None and jump_entry[0][row]:
                    exp, val = jump_entry[1][row].tolist()
                    out.append(f"{plan.jump_text}{exp}, got {val}")
        return errs

    # -- enums -----------------------------------------------------------------------------
    @functools.cached_property
    def enum_groups(self) -> list[tuple[np.ndarray, int, int, int, np.ndarray, list[int]]]:
        """The table-checked enum leaves grouped by (table, field width, shift, mask): per group
        the byte offsets of its fields, so that one gather reads all of them (the 15
        ``visObs[i]`` members of one enum are one group); the other leaves one by one."""
        groups: dict[tuple[str, int, int, int], list[int]] = {}  # the table is the enum's
        fields = self.dtype.fields  # read once: a mapping proxy per access
        assert fields is not None
        for index, check in enumerate(self.enums):
            if check.table is None:
                continue
            dt = fields[check.leaf.field][0]
            mask = check.leaf.mask if check.leaf.mask is not None else (1 << 8 * dt.itemsize) - 1
            groups.setdefault((check.enum, dt.itemsize, check.leaf.shift, mask), []).append(index)
        out = []
        for (_, width, shift, mask), members in groups.items():
            offs = np.array([fields[self.enums[i].leaf.field][1] for i in members], np.intp)
            out.append((offs, width, shift, mask, self.enums[members[0]].table, members))
        return out  # type: ignore[return-value]

    def enum_errors(self, payloads: np.ndarray, name: str, rows: np.ndarray | None = None
                    ) -> dict[int, list[str]]:
        """Rows (of those in ``rows``, default all) with an undefined enum value: the exact
        engine's strings, ``bad enum value V for NAME.PATH (ENUM)``, the first ten."""
        out: dict[int, list[str]] = {}
        if not self.enums or not len(payloads):
            return out
        found: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # enum index -> (bad, values)
        grouped: set[int] = set()
        for offs, width, shift, mask, table, members in self.enum_groups:
            grouped.update(members)
            col = payloads[:, offs]
            if width > 1:  # little-endian fields of ``width`` bytes
                col = col.astype(np.uint64)
                for byte in range(1, width):
                    col |= payloads[:, offs + byte].astype(np.uint64) << np.uint64(8 * byte)
            if shift or mask != (1 << 8 * width) - 1:
                col = (col >> shift) & mask
            bad = table[col]
            if rows is not None:
                bad &= rows[:, None]
            hit = bad.any(axis=0)
            if hit.any():
                for position in np.flatnonzero(hit).tolist():
                    found[members[position]] = (bad[:, position], col[:, position])
        rec = None
        for index, check in enumerate(self.enums):
            if index in grouped:
                continue
            if rec is None:
                rec = self.records(payloads)
            col = self.column(rec, check.leaf)
            bad = check.bad(col)
            if rows is not None:
                bad &= rows
            if bad.any():
                found[index] = (bad, col)
        for index in sorted(found):  # in the reference dissector's order of the leaves
            bad, col = found[index]
            check = self.enums[index]
            for row in np.flatnonzero(bad).tolist():
                lst = out.setdefault(row, [])
                if len(lst) < MAX_ENUM_ERRORS:
                    lst.append(f"bad enum value {int(col[row])} for {name}.{check.label} "
                               f"({check.enum})")
        return out


def _crc_loop(payloads: np.ndarray, plan: CrcPlan) -> np.ndarray:
    """``crc16`` of ``plan`` in every row, by :func:`~eyeq_spi.codec.e2e.plan_crc` (in C)."""
    width = payloads.shape[1]
    buf = memoryview(np.ascontiguousarray(payloads).tobytes())
    return np.array([plan_crc(buf, plan, row * width) for row in range(len(payloads))],
                    np.uint16)


_CACHE: dict[int, tuple[Layout, VecLayout]] = {}


def vec_layout(lay: Layout, cat: Catalog) -> VecLayout:
    """The :class:`VecLayout` of ``lay`` (built once per layout object)."""
    hit = _CACHE.get(id(lay))
    if hit is None or hit[0] is not lay:
        hit = (lay, VecLayout(lay, cat))
        _CACHE[id(lay)] = hit
    return hit[1]
