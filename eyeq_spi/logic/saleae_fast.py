"""The vectorised path of the Saleae readers (numpy), for the common shape of an export: every
row has the header's number of columns, a field is either unquoted or wholly quoted (no quote,
comma or NUL inside), data bytes are empty or ``0xHH``, row types are exactly the spec's. It
computes exactly what the csv loops of :mod:`eyeq_spi.logic.saleae_ref` compute (a property test
compares them on random exports cut at random places) and returns None for any chunk it cannot
take, or whose reading would raise, without touching the readers' state; the csv loop then reads
that chunk and reports the error with its line.

A chunk is cut into a (rows, columns) table of field bounds with a few passes over its bytes;
only the rows that frame transfers (``enable``/``disable``, a new Packet ID) are looked at one by
one, the data bytes of a transfer are one slice of a column.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from eyeq_spi.capture.pcapng_io import Record
from eyeq_spi.errors import InputError
from eyeq_spi.logic.options import MAX_TRANSFER, Route, SpiOptions
from eyeq_spi.logic.saleae_ref import saleae1_records, saleae2_records
from eyeq_spi.logic.saleae_types import (
    ByteSource,
    OpenTransfer,
    Saleae1State,
    Saleae2State,
    seconds,
)

_HEX = np.full(256, -1, dtype=np.int16)
for _c in b"0123456789":
    _HEX[_c] = _c - 48
for _c in b"abcdef":
    _HEX[_c] = _HEX[_c - 32] = _c - 87
_MAX_NAME = 64  # longer analyzer names: the csv loop (the table would be rows x width)


@dataclass
class Table:
    """Field bounds of a chunk's non-empty rows: ``lo``/``hi`` (rows, columns), quotes off."""

    raw: np.ndarray[Any, Any]
    lo: np.ndarray[Any, Any]
    hi: np.ndarray[Any, Any]
    line: np.ndarray[Any, Any]  # 0-based line of each row within the chunk

    def text(self, row: int, col: int) -> str:
        return bytes(self.raw[self.lo[row, col]:self.hi[row, col]]).decode("utf-8", "replace")

    def strings(self, col: int, width: int) -> np.ndarray[Any, Any] | None:
        """The column as a numpy bytes array (``S<width>``), None when a field is longer."""
        lo, n = self.lo[:, col], self.hi[:, col] - self.lo[:, col]
        if len(n) and int(n.max()) > width:
            return None
        w = max(1, int(n.max()) if len(n) else 1)
        k = np.arange(w)
        idx = np.minimum(lo[:, None] + k[None, :], len(self.raw) - 1)
        cells = np.where(k[None, :] < n[:, None], self.raw[idx], 0).astype(np.uint8)
        return np.ascontiguousarray(cells).view(f"S{w}").ravel()

    def bytes_of(self, col: int, rows: np.ndarray[Any, Any]) -> np.ndarray[Any, Any] | None:
        """``_byte`` of the column at ``rows``: -1 for an empty field; None unless every
        field is empty or ``0xHH``/``0XHH``."""
        lo, n = self.lo[rows, col], self.hi[rows, col] - self.lo[rows, col]
        full = n == 4
        if not (full | (n == 0)).all():
            return None
        lo = lo[full]
        raw = self.raw
        if not ((raw[lo] == 48) & ((raw[lo + 1] | 32) == 120)).all():
            return None
        hi_d, lo_d = _HEX[raw[lo + 2]], _HEX[raw[lo + 3]]
        if ((hi_d < 0) | (lo_d < 0)).any():
            return None
        out = np.full(len(rows), -1, dtype=np.int16)
        out[full] = hi_d * 16 + lo_d
        return out


def table(chunk: bytes, ncols: int) -> Table | None:
    """The field table of a chunk of whole lines, None unless it has the simple shape."""
    if not chunk.endswith(b"\n"):
        return None
    raw = np.frombuffer(chunk, dtype=np.uint8)
    nl = np.flatnonzero(raw == 10)
    starts = np.empty(len(nl), dtype=np.int64)
    starts[0] = 0
    starts[1:] = nl[:-1] + 1
    cr = raw == 13
    ends = nl.copy()
    if cr.any():
        before = nl[nl > 0] - 1
        if int(cr.sum()) != int(cr[before].sum()):
            return None  # a carriage return that does not end a line
        ends -= cr[np.maximum(nl - 1, 0)] & (nl > starts)
    if (raw == 0).any():
        return None
    line = np.arange(len(nl))
    if not (ends > starts).all():
        keep = ends > starts
        starts, ends, line = starts[keep], ends[keep], line[keep]
    commas = np.flatnonzero(raw == 44)
    if len(commas) != len(starts) * (ncols - 1):
        return None
    # the commas in line order, ncols - 1 per row: each row's must lie within its line
    cut = commas.reshape(len(starts), ncols - 1)
    if ncols > 1 and ((cut[:, 0] < starts).any() or (cut[:, -1] >= ends).any()):
        return None
    lo = np.concatenate((starts[:, None], cut + 1), axis=1)
    hi = np.concatenate((cut, ends[:, None]), axis=1)
    n_quotes = int(np.count_nonzero(raw == 34))
    if n_quotes:
        size = hi - lo
        at_lo = (raw[np.minimum(lo, len(raw) - 1)] == 34) & (size > 0)
        at_hi = (raw[np.maximum(hi - 1, 0)] == 34) & (size > 0)
        wrapped = at_lo & at_hi & (size >= 2)
        # every quote wraps a field: a quote inside a field (or a quoted comma, which shifts
        # the fields) is left to the csv module
        if (at_lo != at_hi).any() or 2 * int(wrapped.sum()) != n_quotes:
            return None
        lo = lo + wrapped
        hi = hi - wrapped
    return Table(raw, lo, hi, line)


def saleae2_chunk(chunk: bytes, ncols: int, cols: dict[str, int], i_name: int, i_type: int,
                  i_time: int, kinds: dict[str, str], state: Saleae2State, opts: SpiOptions,
                  make_open: Any) -> list[Record] | None:
    tab = table(chunk, ncols)
    if tab is None:
        return None
    types = tab.strings(i_type, 8)
    names = tab.strings(i_name, _MAX_NAME)
    if types is None or names is None:
        return None
    k_start, k_byte, k_end = (kinds[kind].encode() for kind in ("start", "byte", "end"))
    is_e, is_r, is_d = types == k_start, types == k_byte, types == k_end
    if not (is_e | is_r | is_d).all():
        return None
    analyzers = _analyzers(names, state, opts)
    if analyzers is None:
        return None
    keys, name_index, routes = analyzers
    r_rows = np.flatnonzero(is_r)
    per_name = [np.flatnonzero(name_index[r_rows] == idx) for idx in range(len(keys))]
    cells = _cells(tab, cols, r_rows, per_name)
    if cells is None:
        return None
    framing = _frame_rows(tab, is_e, is_r, name_index, keys, i_time, state, make_open)
    if framing is None:
        return None
    open_, jobs, emits = framing
    if jobs and not _fill(jobs, per_name, r_rows, cells):
        return None
    out = [Record(tr.time, route.direction, bytes(tr.lines[route.line]))
           for tr, key in emits for route in routes[key]]
    state.open_.clear()
    state.open_.update(open_)
    state.routes.update(routes)
    state.results += len(r_rows)
    state.enables += int(is_e.sum())
    return out


def _analyzers(names: np.ndarray[Any, Any], state: Saleae2State, opts: SpiOptions
               ) -> tuple[list[str], np.ndarray[Any, Any], dict[str, list[Route]]] | None:
    """The chunk's analyzer names (in order of first use), each row's index into them, and the
    routes of every name (new names routed as the csv loop would); None when two names differ
    only in bytes that are not UTF-8 or a name has no route."""
    uniq, first, name_index = np.unique(names, return_index=True, return_inverse=True)
    keys = [bytes(uniq[idx]).decode("utf-8", "replace") for idx in range(len(uniq))]
    if len(set(keys)) != len(keys):
        return None
    routes = dict(state.routes)
    try:
        for idx in np.argsort(first):
            if keys[idx] not in routes:
                routes[keys[idx]] = opts.routes(keys[idx], len(routes) + 1)
    except InputError:
        return None
    return keys, name_index, routes


_Cells = list[dict[str, tuple[np.ndarray[Any, Any], np.ndarray[Any, Any], bytes | None]]]


def _cells(tab: Table, cols: dict[str, int], r_rows: np.ndarray[Any, Any],
           per_name: list[np.ndarray[Any, Any]]) -> _Cells | None:
    """Per name and line: its data bytes in row order, which of them are present, and the bytes
    as one ``bytes`` when none is empty."""
    data: dict[str, np.ndarray[Any, Any]] = {}
    for name, col in cols.items():
        vals = tab.bytes_of(col, r_rows)
        if vals is None:
            return None
        data[name] = vals
    cells: _Cells = []
    for sel in per_name:
        by_line = {}
        for line, vals in data.items():
            u8, full = vals[sel].astype(np.uint8), vals[sel] >= 0
            by_line[line] = (u8, full, u8.tobytes() if full.all() else None)
        cells.append(by_line)
    return cells


_Job = tuple[int, OpenTransfer, int, int]  # name, transfer, the rows its bytes lie between


def _frame_rows(tab: Table, is_e: np.ndarray[Any, Any], is_r: np.ndarray[Any, Any],
                name_index: np.ndarray[Any, Any], keys: list[str], i_time: int,
                state: Saleae2State, make_open: Any
                ) -> tuple[dict[str, OpenTransfer | None], list[_Job],
                           list[tuple[OpenTransfer, str]]] | None:
    """Walk the enable/disable rows: the transfers open at the end, the byte runs to append to
    each transfer, and the transfers closed (in order). Transfers open before the chunk are
    copied, so the state stays as it was if the chunk is given up."""
    open_: dict[str, OpenTransfer | None] = dict(state.open_)
    opened_at: dict[str, int] = {}
    jobs: list[_Job] = []
    emits: list[tuple[OpenTransfer, str]] = []
    kind_of, name_of = is_e.tolist(), name_index.tolist()
    for row in np.flatnonzero(~is_r).tolist():
        idx = name_of[row]
        key = keys[idx]
        if kind_of[row]:
            prev = open_.get(key)
            if prev is not None:  # reopened: the csv loop would still check its length
                if key not in opened_at:
                    prev = _copy(prev, make_open)
                jobs.append((idx, prev, opened_at.get(key, -1), row))
            try:
                time = seconds(tab.text(row, i_time))
            except ValueError:
                return None
            open_[key] = make_open(time)
            opened_at[key] = row
            continue
        tr = open_.pop(key, None)
        if tr is None:
            continue
        if key not in opened_at:
            tr = _copy(tr, make_open)  # open before this chunk: the state stays as it was
        jobs.append((idx, tr, opened_at.pop(key, -1), row))
        emits.append((tr, key))
    index = {key: idx for idx, key in enumerate(keys)}
    for key, tr in open_.items():
        if tr is None or key not in index:
            continue
        if key not in opened_at:
            tr = open_[key] = _copy(tr, make_open)
        jobs.append((index[key], tr, opened_at.get(key, -1), len(tab.lo)))
    return open_, jobs, emits


def _fill(jobs: list[_Job], per_name: list[np.ndarray[Any, Any]], r_rows: np.ndarray[Any, Any],
          cells: _Cells) -> bool:
    """Append each job's data bytes to its transfer; False when one grows over the limit."""
    job_names = np.array([job[0] for job in jobs])
    after = np.array([job[2] for job in jobs])
    before = np.array([job[3] for job in jobs])
    starts = np.empty(len(jobs), dtype=np.int64)
    stops = np.empty(len(jobs), dtype=np.int64)
    for idx, sel in enumerate(per_name):
        mine = job_names == idx
        starts[mine] = np.searchsorted(r_rows[sel], after[mine], "right")
        stops[mine] = np.searchsorted(r_rows[sel], before[mine], "left")
    for (idx, tr, _, _), start, stop in zip(jobs, starts.tolist(), stops.tolist(), strict=True):
        for line, (u8, full, blob) in cells[idx].items():
            buf = tr.lines[line]
            buf += (blob[start:stop] if blob is not None
                    else u8[start:stop][full[start:stop]].tobytes())
            if len(buf) > MAX_TRANSFER:
                return False
    return True


def _copy(tr: OpenTransfer, make_open: Any) -> OpenTransfer:
    new: OpenTransfer = make_open(tr.time)
    for line, buf in tr.lines.items():
        new.lines[line] = bytearray(buf)
    return new


def saleae1_chunk(chunk: bytes, ncols: int, i_time: int, i_id: int, i_mosi: int, i_miso: int,
                  state: Saleae1State, routes: list[Route], make_open: Any
                  ) -> list[Record] | None:
    t = table(chunk, ncols)
    if t is None:
        return None
    rows = len(t.lo)
    if rows == 0:
        return []
    pids = t.strings(i_id, 64)
    if pids is None or (pids.view(np.uint8) >= 128).any():
        return None
    lo, hi = t.lo[:, i_id], t.hi[:, i_id]
    if not (hi > lo).all() or (t.raw[lo] <= 32).any() or (t.raw[hi - 1] <= 32).any():
        return None  # an empty Packet ID (an error) or spaces that strip() would take
    all_rows = np.arange(rows)
    data = {"mosi": t.bytes_of(i_mosi, all_rows), "miso": t.bytes_of(i_miso, all_rows)}
    if data["mosi"] is None or data["miso"] is None:
        return None
    new = np.flatnonzero(pids[1:] != pids[:-1]) + 1
    tr, packet = state.tr, state.packet
    first = t.text(0, i_id)
    if first != packet:
        new = np.concatenate(([0], new))
    elif tr is not None:
        tr = _copy(tr, make_open)
    bounds = np.concatenate((new, [rows])).tolist()
    out: list[Record] = []
    start = 0
    for b in bounds:
        if tr is not None:
            for line, vals in data.items():
                assert vals is not None
                v = vals[start:b]
                tr.lines[line] += v[v >= 0].astype(np.uint8).tobytes()
                if len(tr.lines[line]) > MAX_TRANSFER:
                    return None
        if b == rows:
            break
        if tr is not None:
            out += (Record(tr.time, r.direction, bytes(tr.lines[r.line])) for r in routes)
        try:
            tr = make_open(seconds(t.text(b, i_time)))
        except ValueError:
            return None
        start = b
    state.tr = tr
    state.packet = t.text(rows - 1, i_id)
    return out


def read_saleae2(src: ByteSource, opts: SpiOptions, *, chunk_size: int = 1 << 20
                 ) -> Iterator[Record]:
    """The Logic 2 reader: each chunk through :func:`saleae2_chunk` while it keeps succeeding,
    else through the reference's csv loop."""
    return saleae2_records(src, opts, chunk_size, saleae2_chunk)


def read_saleae1(src: ByteSource, opts: SpiOptions, *, chunk_size: int = 1 << 20
                 ) -> Iterator[Record]:
    """The Logic 1.x reader, as :func:`read_saleae2`."""
    return saleae1_records(src, opts, chunk_size, saleae1_chunk)
