"""The fast path in front of the one :class:`~.engine.Dissector`: numpy over whole chunks, the
dissector's own per-transfer path wherever anything is unusual.

Theory of operation
-------------------
:func:`~.engine_fast_frames.frame_arrays` judges a chunk of transfers at once; every frame record
comes from these arrays. Per direction the pass is in one of two modes:

- **reference**: each transfer goes through :meth:`.engine.Dissector.feed`;
- **fast**: a *span* of clean frames inside one chunk (128 bytes, good CRC, DATA, R = 0, a valid
  transport header, NUM = the previous NUM + 1) forming whole transfers, each frame within the
  reassembly timeout of the one before; only the last transfer may still be open.

A direction enters fast mode only where the dissector's state is known through its public API:
the previous DATA frame of that direction completed a message, the receiver expects the span's
first NUM (:meth:`~.engine.Dissector.expected_num`), and the span has at least ``MIN_SPAN``
frames. A span's messages are handed to :meth:`~.engine.Dissector.accept_clean` (DASP and 0x41
groups judged at once against :meth:`~.engine.Dissector.message_state`).

A span ends at the first frame that is not clean, at the open transfer's reassembly deadline,
before the other direction's DATA frame with NUM 0 and RSP 0 (L4: the reference restarts this
direction's receiver there too), or at the end of its chunk. There the dissector takes the
direction up again (:meth:`~.engine.Dissector.resume`) and judges what follows itself. Timers of
reference directions run before the first record at or past the earliest deadline, as ``feed``
would run them.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eyeq_spi.capture.pcapng_fast import DIR_NAME, Chunk
from eyeq_spi.catalog.link import link_spec
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect.engine import Dissector, TransferFrames
from eyeq_spi.dissect.engine_fast_frames import DATA, FrameArrays, FrameBlock, frame_arrays
from eyeq_spi.dissect.engine_fast_messages import SpanDecoder, SpanMessage
from eyeq_spi.link.connection import LinkConfig
from eyeq_spi.link.frame import SEQ_MODULO
from eyeq_spi.transport.segment import (
    CONSECUTIVE,
    CONSECUTIVE_CHUNK,
    FIRST,
    FIRST_CHUNK,
    FIRST_TOTAL_MIN,
    SINGLE,
    SINGLE_MAX,
)

_T = link_spec()["transport"]
WINDOW: int = LinkConfig().window
MIN_SPAN = 2 * WINDOW
REASSEMBLY_TIMEOUT: float = _T["reassembly_timeout"]
RECEIVE_LIMIT = {"h2e": int(_T["receive_limit"]["eyeq"]), "e2h": int(_T["receive_limit"]["host"]),
                 None: int(_T["receive_limit"]["host"])}

Item = dict[str, Any] | FrameBlock


@dataclass
class _Plan:
    """One direction's fed rows in the current chunk and their per-row checks (as lists)."""

    rows: list[int] = field(default_factory=list)
    okf: list[bool] = field(default_factory=list)
    ttype: list[int] = field(default_factory=list)
    need: list[int] = field(default_factory=list)  # consecutive frames a first frame needs
    cont: list[bool] = field(default_factory=list)
    # breaks[i] = rows among [0, i) that cannot continue a transfer
    breaks: list[int] = field(default_factory=lambda: [0])
    ip: int = 0  # next row (index into rows) for the reference


@dataclass
class Unit:
    """One transfer of a span: its first and one past its last index into the plan's rows."""

    ks: int
    ke: int
    first: bool


@dataclass
class Dir:
    """One direction's mode (reference or fast) and its span in the current chunk."""

    name: str | None
    code: int
    fast: bool = False
    canonical: bool = False  # reference mode: the last fed frame completed a message
    units: list[Unit] = field(default_factory=list)
    ui: int = 0  # next unit to emit
    stop_k: int = 0  # index into the plan's rows of the first frame not in the span
    open_ks: int = -1  # index into the plan's rows of the open transfer's first frame, -1: none
    switch_row: int = 0
    plan: _Plan = field(default_factory=_Plan)  # of the current chunk


class ChunkFeeder:
    """Chunks in, records (dicts) and :class:`FrameBlock` items out, in capture order."""

    def __init__(self, sw: str | None = None, codec: MessageCodec | None = None,
                 *, fields: str = "dict") -> None:
        self.dis = Dissector(sw, codec)
        self.decode = SpanDecoder(self.dis, fields=fields)  # engine_fast_messages.FIELD_MODES
        self.base = 0
        self.dirs: dict[int, Dir] = {}
        self.deadline: float | None = None
        self._restarts: tuple[np.ndarray, np.ndarray] = (np.zeros(0, np.int64),) * 2

    # -- driving -----------------------------------------------------------------------------
    def feed(self, chunk: Chunk) -> Iterator[Item]:
        if not len(chunk):
            return
        fa = frame_arrays(chunk, self.dis.frames, self.base, self.dis.last_time)
        yield from self._chunk(fa)
        self.base += len(chunk)
        self.dis.index = self.base

    def finish(self) -> Iterator[Item]:
        self.dis.index = self.base
        yield from self.dis.finish()

    # -- one chunk -----------------------------------------------------------------------------
    def _chunk(self, fa: FrameArrays) -> Iterator[Item]:
        row_count = len(fa)
        codes, first = np.unique(fa.chunk.direction, return_index=True)
        for code in [int(c) for c in codes[np.argsort(first)]]:
            name = DIR_NAME[code]
            self.dis.open_direction(name)  # receivers made in the order feed() would
            self.dirs.setdefault(code, Dir(name, code))
        for st in self.dirs.values():
            st.plan = self._plan(fa, st)
        # L4 frames (DATA, NUM 0, RSP 0, CRC good): the rows and their directions
        l4 = np.flatnonzero(fa.fed & fa.crc_ok & (fa.ftype == DATA) & (fa.num == 0)
                            & (fa.rsp == 0))
        self._restarts = (l4, fa.chunk.direction[l4])
        times = fa.chunk.time
        pos = 0
        while pos < row_count:
            nxt, why, which = row_count, 0, -1
            for code, st in self.dirs.items():
                pl = st.plan
                if st.fast:  # at a tie, the span ends before the other direction's record
                    if st.switch_row <= nxt:
                        nxt, why, which = st.switch_row, 1, code
                elif pl.ip < len(pl.rows) and pl.rows[pl.ip] < nxt:
                    nxt, why, which = pl.rows[pl.ip], 2, code
            if self.deadline is not None and nxt > pos:
                late = np.flatnonzero(times[pos:nxt] >= self.deadline)
                if late.size:
                    nxt, why = pos + int(late[0]), 3
            if nxt > pos:
                yield self._emit(fa, pos, nxt)
            if nxt >= row_count:
                break
            if why == 3:  # the engine's timers first, as feed() would run them
                self.dis.index = fa.base + nxt + 1
                yield from self.dis.run_timers(float(times[nxt]))
                self._update_deadline()
                yield self._emit(fa, nxt, nxt + 1)
                pos = nxt + 1
                continue
            st = self.dirs[which]
            pl = st.plan
            if why == 1:
                self._to_reference(st, fa)
                pl.ip = st.stop_k
                pos = nxt
                continue
            if st.canonical and self._try_span(fa, st):
                pos = nxt
                continue
            self.dis.index = fa.base + nxt
            out = list(self.dis.feed(fa.chunk.transfer(nxt)))
            yield from out
            idx = fa.base + nxt
            st.canonical = any(r["kind"] == "message" and r["direction"] == st.name
                               and r["frames"] and r["frames"][-1] == idx for r in out)
            pl.ip += 1
            self._update_deadline()
            pos = nxt + 1
        self.dis.index = fa.base + row_count
        t_end = fa.tfill[row_count - 1]
        self.dis.last_time = None if t_end != t_end else float(t_end)
        for st in self.dirs.values():  # a span ends with its chunk: the reference takes up
            if st.fast:
                self._to_reference(st, fa)

    def _update_deadline(self) -> None:
        self.deadline = self.dis.next_deadline()

    # -- planning ------------------------------------------------------------------------------
    def _plan(self, fa: FrameArrays, st: Dir) -> _Plan:
        sel = np.flatnonzero(fa.fed & (fa.chunk.direction == st.code))
        if not sel.size:
            return _Plan()
        data = fa.chunk.data
        tt = data[sel, 6].astype(np.int64)
        size = data[sel, 7].astype(np.int64)
        total = data[sel, 8:12].copy().view("<u4")[:, 0].astype(np.int64)
        limit = RECEIVE_LIMIT[st.name]
        clean = fa.crc_ok[sel] & (fa.ftype[sel] == DATA)
        hdr = (((tt == SINGLE) & (size >= 1) & (size <= SINGLE_MAX))
               | ((tt == FIRST) & (total >= FIRST_TOTAL_MIN) & (total <= limit))
               | (tt == CONSECUTIVE))
        okf = clean & hdr
        num = fa.num[sel]
        prev = np.empty_like(num)
        prev[1:] = num[:-1]
        prev[0] = -2  # a span starts inside its chunk (its first NUM is checked against E)
        cont = num == (prev + 1) % SEQ_MODULO
        # the reassembly deadline each fed frame sets, against the latest time of any record
        # after it up to and including the next fed frame (the engine runs its timers first)
        times = fa.chunk.time
        t_sel = times[sel]
        dl = np.where(np.isnan(t_sel), 0.0, t_sel) + REASSEMBLY_TIMEOUT
        tm = np.where(np.isnan(times), -np.inf, times)
        seg_max = np.maximum.reduceat(np.append(tm, -np.inf), np.append(0, sel + 1))
        gap = np.empty(sel.size, bool)
        gap[1:] = seg_max[1:-1] < dl[:-1]
        gap[0] = True
        tid = data[sel, 7].astype(np.int64)
        link = okf & (tt == CONSECUTIVE) & cont & gap
        link[1:] &= tid[1:] == tid[:-1]
        link[0] = False
        need = np.where(tt == FIRST,
                        -(-(np.maximum(total, FIRST_TOTAL_MIN) - FIRST_CHUNK)
                          // CONSECUTIVE_CHUNK), 0)
        self._padding(data, sel, tt, total, need, link)
        bad = np.concatenate([[0], np.cumsum(~link)])
        return _Plan(sel.tolist(), okf.tolist(), tt.tolist(), need.tolist(), cont.tolist(),
                     bad.tolist())

    @staticmethod
    def _padding(data: Any, sel: Any, tt: Any, total: Any, need: Any, link: Any) -> None:
        """T6a: the last consecutive frame of a transfer carries zeros after the message's last
        byte. Where it does not, that frame is no link of a clean span, so the reference
        judges it (it NAKs the frame 0x011 and aborts the transfer as ``bad_padding``)."""
        fk = np.flatnonzero(tt == FIRST)
        needs = need[fk]
        last = fk + needs
        takes = total[fk] - FIRST_CHUNK - (needs - 1) * CONSECUTIVE_CHUNK
        inside = last < sel.size
        lasts, takes = last[inside], takes[inside]
        if not lasts.size:
            return
        rows = data[sel[lasts]]
        pad = np.arange(rows.shape[1])[None, :] >= (8 + takes)[:, None]
        link[lasts[((rows != 0) & pad).any(axis=1)]] = False

    def _walk(self, fa: FrameArrays, st: Dir, k0: int, limit: int) -> int:
        """The span from rows[k0] (its first NUM was checked against E) up to row ``limit``:
        complete units, open transfer, stop index and switch row. Returns the number of frames
        it covers."""
        pl = st.plan
        rows, okf, tt, need, cont, breaks = (pl.rows, pl.okf, pl.ttype, pl.need, pl.cont,
                                             pl.breaks)
        end = bisect.bisect_left(rows, limit)
        units: list[Unit] = []
        index = k0
        st.open_ks = -1
        while index < end and okf[index] and (index == k0 or cont[index]):
            kind = tt[index]
            if kind == SINGLE:
                units.append(Unit(index, index + 1, False))
                index += 1
            elif kind == FIRST:
                needed = need[index]
                last = min(index + needed, end - 1)
                nbad = breaks[last + 1] - breaks[index + 1]
                if nbad == 0 and index + needed < end:
                    units.append(Unit(index, index + needed + 1, True))
                    index += needed + 1
                    continue
                st.open_ks = index
                index = (end if nbad == 0
                         else bisect.bisect_left(breaks, breaks[index + 1] + 1) - 1)
                break
            else:
                break
        st.units, st.ui, st.stop_k = units, 0, index
        # switch at the first frame outside the span, or before it at the first transfer at or
        # past the open transfer's reassembly deadline
        row = rows[index] if index < end else limit
        if st.open_ks >= 0:
            last_row = rows[index - 1]
            tr = float(fa.chunk.time[last_row])
            late = np.flatnonzero(fa.chunk.time[last_row + 1 : row]
                                  >= (0.0 if tr != tr else tr) + REASSEMBLY_TIMEOUT)
            if late.size:
                row = last_row + 1 + int(late[0])
        st.switch_row = row
        return index - k0

    def _try_span(self, fa: FrameArrays, st: Dir) -> bool:
        index = st.plan.ip
        if int(fa.num[st.plan.rows[index]]) != self.dis.expected_num(st.name):
            return False
        rows, codes = self._restarts
        later = rows[(rows > st.plan.rows[index]) & (codes != st.code)]
        if self._walk(fa, st, index, int(later[0]) if later.size else len(fa)) < MIN_SPAN:
            return False
        st.fast = True
        return True

    # -- output ------------------------------------------------------------------------------
    def _emit(self, fa: FrameArrays, lo: int, hi: int) -> FrameBlock:
        block = FrameBlock(fa, lo, hi)
        done: list[tuple[int, Dir, Unit]] = []
        for st in self.dirs.values():
            if not st.fast:
                continue
            rows = st.plan.rows
            while st.ui < len(st.units):
                unit = st.units[st.ui]
                row = rows[unit.ke - 1]
                if row >= hi:
                    break
                done.append((row, st, unit))
                st.ui += 1
        if len(done) > 1:
            done.sort(key=lambda x: x[0])
        records = self.decode.records(self._messages(fa, done))
        block.messages = [(row, rec) for (row, _, _), rec in zip(done, records, strict=True)]
        block.tables = self.decode.tables
        time_s = fa.tfill[hi - 1]
        self.dis.last_time = None if time_s != time_s else float(time_s)
        return block

    def _frames(self, fa: FrameArrays, st: Dir, ks: int, ke: int) -> TransferFrames:
        """Frames rows[ks:ke] of this chunk."""
        times, nums, data = fa.lst("time"), fa.lst("num"), fa.chunk.data
        return [(data[row].tobytes(), None if times[row] != times[row] else times[row],
                 nums[row], fa.base + row) for row in st.plan.rows[ks:ke]]

    def _messages(self, fa: FrameArrays, done: list[tuple[int, Dir, Unit]]
                  ) -> list[SpanMessage]:
        """The messages of ``done`` (in order), cut from one copy of all their rows' transport
        payloads (a transfer's frames are consecutive there); the receivers' NUM -> index maps
        end as the reference's sequential updates leave them."""
        out: list[SpanMessage] = []
        rows: list[int] = []
        for _, st, unit in done:
            rows += st.plan.rows[unit.ks : unit.ke]
        width = fa.chunk.data.shape[1] - 8
        blob = fa.chunk.data[rows, 8:].tobytes() if rows else b""
        tid_col, nums, tfill = fa.lst("tid"), fa.lst("num"), fa.lst("tfill")
        pos = 0  # next row of ``rows``
        noted: dict[str | None, tuple[list[int], list[int]]] = {}  # NUMs, indices in order
        for row, st, unit in done:
            mine = st.plan.rows[unit.ks : unit.ke]
            offset = pos * width
            pos += len(mine)
            if unit.first:  # bytes 8..11 of the first frame: the total (T1)
                total = int.from_bytes(blob[offset : offset + 4], "little")
                data = blob[offset + 4 : min(offset + 4 + total, pos * width)]
                tid: int | None = tid_col[mine[0]]
            else:  # byte 7 of a single frame: its size
                data, tid = blob[offset : offset + tid_col[mine[0]]], None
            frame_nums = tuple([nums[fed_row] for fed_row in mine])
            indices = [fa.base + fed_row for fed_row in mine]
            seen = noted.setdefault(st.name, ([], []))
            seen[0].extend(frame_nums)
            seen[1].extend(indices)
            time_s = tfill[row]
            out.append(SpanMessage(st.name, data, frame_nums, tid,
                                   None if time_s != time_s else time_s, list(indices)))
        for name, (frame_nums_all, indices_all) in noted.items():
            self.dis.note_frames(name, frame_nums_all, indices_all)
        return out

    # -- span state: what the receiver would hold --------------------------------------------
    def _state(self, st: Dir, fa: FrameArrays
               ) -> tuple[list[TransferFrames], TransferFrames | None, TransferFrames | None]:
        """(last complete units with at least WINDOW frames, oldest first; the last complete
        multi-frame transfer; the open transfer) of the span so far."""
        opened = self._frames(fa, st, st.open_ks, st.stop_k) if st.open_ks >= 0 else None
        units: list[TransferFrames] = []
        last_first: TransferFrames | None = None
        count = 0
        for unit in reversed(st.units):
            if count >= WINDOW and last_first is not None:
                break
            if count < WINDOW or unit.first:
                fr = self._frames(fa, st, unit.ks, unit.ke)
                if count < WINDOW:
                    units.append(fr)
                    count += len(fr)
                if unit.first and last_first is None:
                    last_first = fr
        units.reverse()
        return units, last_first, opened

    def _to_reference(self, st: Dir, fa: FrameArrays) -> None:
        """The reference takes the direction up again where the span ended (its receiver is
        given the span's last transfers: :meth:`.engine.Dissector.resume`)."""
        units, last_first, opened = self._state(st, fa)
        st.fast = st.canonical = False
        self.dis.resume(st.name, last_first, units, opened)
        self._update_deadline()


def iter_items(chunks: Iterable[Chunk], *, sw: str | None = None,
               codec: MessageCodec | None = None, fields: str = "dict") -> Iterator[Item]:
    """Frame blocks and records (dicts where the reference reads), in capture order;
    ``fields``: what clean spans' messages carry (:class:`.engine_fast_messages.SpanDecoder`)."""
    feeder = ChunkFeeder(sw, codec, fields=fields)
    for chunk in chunks:
        yield from feeder.feed(chunk)
    yield from feeder.finish()


def iter_records(chunks: Iterable[Chunk], *, sw: str | None = None,
                 codec: MessageCodec | None = None, fields: str = "dict"
                 ) -> Iterator[dict[str, Any]]:
    """Every record, as :func:`.engine.iter_records` gives them."""
    for item in iter_items(chunks, sw=sw, codec=codec, fields=fields):
        if isinstance(item, FrameBlock):
            yield from item.records()
        else:
            yield item
