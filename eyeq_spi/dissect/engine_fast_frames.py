"""Frames judged many at a time: header fields (L1, with the :class:`FrameCodec`'s own shifts),
CRC (L3, two bytes per step through a table built from the codec's CRC function) and frame
records from ``(N, 128)`` arrays; :class:`FrameBlock` turns a range of them into records or
``--stats`` counts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eyeq_spi.capture.pcapng_fast import DIR_NAME, Chunk
from eyeq_spi.codec.message_fast import crc_word_tables
from eyeq_spi.dissect.engine import frame_record
from eyeq_spi.errors import InputError
from eyeq_spi.link.frame import FRAME_SIZE, FrameCodec, FrameKind

# frame_type codes
DATA, ACK, NAK, INVALID = 0, 1, 2, 3
TYPE_NAMES = ("DATA", "ACK", "NAK", "INVALID")
_TABLES: dict[int, np.ndarray | None] = {}


def crc_table(codec: FrameCodec) -> np.ndarray | None:
    """T[v] = the CRC register after two more bytes, for every 16-bit value ``v`` of (register
    XOR the two bytes), built from the codec's own CRC function (so it is the codec's variant).
    Only a non-reflected CRC-16 with xorout 0 has this form (L3's CCITT-FALSE does); for any other
    the table fails its check and None is returned: the fast path then is not used."""
    key = id(codec.crc)
    if key in _TABLES:
        return _TABLES[key]
    init = codec.crc(b"")
    table: np.ndarray = crc_word_tables(codec.crc)[1]
    for size in (2, 4, 126):  # a byte pattern that reaches every bit of the table's index
        msg = bytes((i * 167 + 13 * size) & 0xFF for i in range(size))
        words = np.frombuffer(msg, ">u2").reshape(-1, 1)
        if int(crc_of_words(words, init, table, size // 2)[0]) != codec.crc(msg):
            _TABLES[key] = None
            return None
    _TABLES[key] = table
    return table


def crc_of_words(words: np.ndarray, init: int, table: np.ndarray, steps: int) -> np.ndarray:
    """CRC of the first ``steps`` big-endian 16-bit words of every row of ``words`` (k, n)."""
    crc = np.full(words.shape[1], init, np.uint16)
    for step in range(steps):
        crc = table[crc ^ words[step]]
    return crc


@dataclass
class FrameArrays:
    """One chunk of transfers, judged."""

    chunk: Chunk
    base: int  # index of row 0 in the capture
    ftype: np.ndarray  # int8, DATA/ACK/NAK/INVALID
    num: np.ndarray  # int64
    rsp: np.ndarray
    crc_ok: np.ndarray  # bool
    d: np.ndarray  # D field
    fed: np.ndarray  # bool: goes to the passive receiver (everything but ACK/NAK frame types)
    tfill: np.ndarray  # float64: time of the last record with a time at or before each row
    r: np.ndarray  # R field
    _lists: dict[str, list[Any]] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.chunk)

    def lst(self, name: str) -> list[Any]:
        """A column as a Python list (cached): per-row Python work reads lists, not arrays.
        ``ttype`` and ``tid`` are the transport bytes 6 and 7."""
        out = self._lists.get(name)
        if out is None:
            if name in ("ttype", "tid"):
                arr = self.chunk.data[:, 6 if name == "ttype" else 7]
            else:
                arr = getattr(self.chunk if name in ("length", "time", "direction") else self, name)
            out = self._lists[name] = arr.tolist()
        return out


def validate(data: np.ndarray, length: np.ndarray, codec: FrameCodec
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Header fields (D, R, RSP, NUM) and CRC verdict (L3 coverage by D) of every row of an
    ``(N, 128)`` array: the vectorised frame check."""
    word = data[:, 0:4].copy().view("<u4")[:, 0].astype(np.int64)
    d_field, r_field, rsp, num = (np.asarray(x) for x in codec.unpack_header(word))  # type: ignore[arg-type]
    got = data[:, 4:6].copy().view("<u2")[:, 0]
    table = crc_table(codec)
    if table is None:
        raise InputError("the link CRC variant has no 16-bit table form: use the hex format or "
                         "another CRC variant")
    control = (d_field == FrameKind.ACK) | (d_field == FrameKind.NAK)
    hdr, crc, rows = _frame_crcs(np.ascontiguousarray(data), control, codec.crc(b""), table)
    full = hdr.copy()  # control frames: the header's CRC only (L3)
    full[rows] = crc
    crc_ok = np.where(control, hdr == got, full == got) & (length == FRAME_SIZE)
    return d_field, r_field, rsp, num, crc_ok


_SWAPPED: dict[int, np.ndarray] = {}
BLOCK_ROWS = 8192  # rows whose words are transposed at a time (about 1 MB: in cache)


def _swapped(table: np.ndarray) -> np.ndarray:
    """The word table for byte-swapped registers fed little-endian words:
    ``S[v] = swap(T[swap(v)])``. A register ``s = swap(crc)`` steps as ``S[s ^ le_word]``
    exactly when ``crc`` steps as ``T[crc ^ be_word]``, so the rows' words are read as they lie
    in memory, with no byte swap per word."""
    key = id(table)
    out = _SWAPPED.get(key)
    if out is None:
        out = _SWAPPED[key] = table[np.arange(65536, dtype=np.uint16).byteswap()].byteswap()
    return out


def _frame_crcs(data: np.ndarray, control: np.ndarray, init: int, table: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the header's CRC of every row, the whole frame's CRC of the rows that are not control
    frames, those rows' indices): L3 covers the header, then the data after the CRC field, as
    big-endian 16-bit words; a control frame's CRC covers its header only, so its data is not
    stepped through. Words are transposed a block of rows at a time."""
    sw = _swapped(table)
    words = data.view("<u2")  # (n, 64): 0-1 the header, 2 the CRC field, 3.. the data
    row_count = len(words)
    swapped = np.full(row_count, ((init >> 8) | (init << 8)) & 0xFFFF, np.uint16)
    for step in (0, 1):
        swapped = sw[swapped ^ words[:, step]]
    rows = np.flatnonzero(~control)
    dw = words[:, 3:] if rows.size == row_count else words[rows, 3:]
    out = swapped[rows]
    tmp = np.empty(min(len(rows), BLOCK_ROWS), np.uint16)
    for b0 in range(0, len(rows), BLOCK_ROWS):
        wt = np.ascontiguousarray(dw[b0 : b0 + BLOCK_ROWS].T)
        block = out[b0 : b0 + BLOCK_ROWS]
        scratch = tmp[: len(block)]
        for step in range(len(wt)):
            np.bitwise_xor(block, wt[step], out=scratch)
            np.take(sw, scratch, out=block)
    return swapped.byteswap(), out.byteswap(), rows


def frame_arrays(chunk: Chunk, codec: FrameCodec, base: int, last_time: float | None
                 ) -> FrameArrays:
    row_count = len(chunk)
    d_field, r_field, rsp, num, crc_ok = validate(chunk.data, chunk.length, codec)
    ok128 = chunk.length == FRAME_SIZE
    ftype = np.full(row_count, INVALID, np.int8)
    valid = ok128 & (r_field == 0)
    ftype[valid & (d_field == FrameKind.DATA)] = DATA
    ftype[valid & (d_field == FrameKind.ACK)] = ACK
    ftype[valid & (d_field == FrameKind.NAK)] = NAK
    fed = (ftype != ACK) & (ftype != NAK)
    times = chunk.time
    has = ~np.isnan(times)
    pos = np.where(has, np.arange(row_count), -1)
    np.maximum.accumulate(pos, out=pos)
    first = np.nan if last_time is None else last_time
    tfill = np.where(pos >= 0, times[np.maximum(pos, 0)], first)
    return FrameArrays(chunk, base, ftype, num, rsp, crc_ok, d_field, fed, tfill, r_field)


@dataclass
class FrameBlock:
    """Frame records of rows ``[lo, hi)`` of one chunk, with the messages that complete inside
    it: ``messages[i] = (row, record)`` comes right after the frame record of ``row``."""

    fa: FrameArrays
    lo: int
    hi: int
    messages: list[tuple[int, dict[str, Any]]] = field(default_factory=list)
    # engine_fast_messages.ColumnGroup, "columns" mode
    tables: list[Any] = field(default_factory=list)

    def frame(self, index: int) -> dict[str, Any]:
        """The frame record of row ``i`` (:func:`.engine.frame_record`)."""
        fa = self.fa
        column = fa.lst
        time_s = column("time")[index]
        length = column("length")[index]
        return frame_record(fa.base + index, None if time_s != time_s else time_s,
                            DIR_NAME[column("direction")[index]], length,
                            (column("d")[index], column("r")[index],
                             column("rsp")[index], column("num")[index]),
                            bool(column("crc_ok")[index]),
                            (column("ttype")[index], column("tid")[index]))

    def records(self) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = []
        msgs = iter(self.messages)
        nxt = next(msgs, None)
        for row in range(self.lo, self.hi):
            out.append(self.frame(row))
            while nxt is not None and nxt[0] == row:
                out.append(nxt[1])
                nxt = next(msgs, None)
        return out

    def add_to(self, stats: Any) -> None:
        """Count this block's frames and messages into a :class:`~.stats.Stats`."""
        fa = self.fa
        lo, hi = self.lo, self.hi
        ft = fa.ftype[lo:hi]
        counts = np.bincount(ft, minlength=4)
        for code, count in enumerate(counts.tolist()):
            if count:
                stats.frames[TYPE_NAMES[code]] += count
        bad_len = fa.chunk.length[lo:hi] != FRAME_SIZE
        stats.bad_length += int(bad_len.sum())
        ok = fa.crc_ok[lo:hi]
        stats.crc_errors += int((~ok & ~bad_len).sum())
        naks = (ft == NAK) & ok
        if naks.any():
            vals, cnt = np.unique(fa.num[lo:hi][naks], return_counts=True)
            for value, count in zip(vals.tolist(), cnt.tolist(), strict=True):
                stats.nak_reasons[f"0x{value:03X}"] += count
        for _, rec in self.messages:
            stats.add(rec)
