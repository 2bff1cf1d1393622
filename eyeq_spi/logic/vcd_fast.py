"""The vectorised path of the VCD reader (numpy), for the common shapes of a VCD body: value
changes and ``#time`` tokens separated by newlines or spaces (one change per line as simulators
and our writer put them, or ``#time 1! 0"`` lines as sigrok and PulseView do), one-character
identifiers, plain ``0``/``1`` values. It computes exactly what the token loop of
:mod:`eyeq_spi.logic.vcd_ref` computes (property tests compare them on random waveforms in both
layouts cut at random places, and on a VCD written by the real ``sigrok-cli``) and returns None
for any chunk it cannot take, which the token loop then reads; a head it cannot take
(``$dumpvars``...) goes to the token loop and the rest stays here.

Per SPI channel, each line is worked on as its own subsequence of changes: chip select edges
split the sampling clock edges into transfers, the data lines' levels at those edges are found
with ``searchsorted`` and the bits packed with ``numpy.packbits``; times are parsed only where a
transfer starts. The open transfer at the end of a chunk is carried in the channel's state.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any, Literal

import numpy as np

from eyeq_spi.capture.pcapng_io import Record
from eyeq_spi.errors import InputError
from eyeq_spi.logic.options import MAX_TRANSFER, SpiOptions
from eyeq_spi.logic.saleae_types import ByteSource
from eyeq_spi.logic.vcd_ref import vcd_records
from eyeq_spi.logic.vcd_types import Chan, ReaderState

_IGNORED = -1


class FastPath:
    def __init__(self, lut: np.ndarray[Any, Any], chans: list[Chan]) -> None:
        self.lut = lut  # identifier byte -> channel * 4 + role, or -1
        self.chans = chans

    @classmethod
    def build(cls, table: dict[bytes, list[tuple[Chan, int]]]) -> FastPath | None:
        lut = np.full(256, _IGNORED, dtype=np.int64)
        chans: list[Chan] = []
        for ident, targets in table.items():
            if len(ident) != 1 or len(targets) != 1:
                return None  # longer identifiers or a line feeding two roles: token loop
            ch, role = targets[0]
            if ch not in chans:
                chans.append(ch)
            lut[ident[0]] = chans.index(ch) * 4 + role
        return cls(lut, chans)

    def run(self, reader: ReaderState, chunk: bytes) -> list[Record] | int | None:
        """The records of ``chunk``; or the length of a head of it (up to the last line this
        path cannot take, in its first half: ``$dumpvars``...) for the token loop to read
        first; or None when the token loop must read it all."""
        if chunk[-1:] not in (b"\n", b" "):
            return None
        raw = np.frombuffer(chunk, dtype=np.uint8)
        # tokens end at a newline or a space: one change per line, or sigrok's and
        # PulseView's "#time 1! 0\"" lines
        nl = np.flatnonzero((raw == 10) | (raw == 32))
        n_lines = len(nl)
        starts = np.empty(len(nl), dtype=np.int64)
        starts[0] = 0
        starts[1:] = nl[:-1] + 1
        lens = nl - starts
        if not lens.all():
            keep = lens > 0
            starts, lens, nl = starts[keep], lens[keep], nl[keep]
        if len(starts) == 0:
            return []
        first = raw[starts]
        is_val = (lens == 2) & ((first == 48) | (first == 49))
        is_time = (first == 35) & (lens >= 2) & (lens <= 19)
        ok = is_val | is_time
        if len(ok) and not ok[-1]:
            return None
        if not ok.all():  # $dumpvars, x/z, vectors, comments, CRLF, long identifiers...
            cut = int(nl[np.flatnonzero(~ok)[-1]]) + 1
            return cut if cut <= len(chunk) // 2 else None
        t_pos = starts[is_time]
        v_pos = starts[is_val]
        idents = raw[v_pos + 1]
        # every time is digits only (else the token loop reports it; times are parsed on
        # demand): the bytes that are not digits are exactly the newlines, the '#'s and the
        # identifiers that are not digits
        other = np.count_nonzero(raw < 48) + np.count_nonzero(raw > 57)
        if other != n_lines + len(t_pos) + len(idents) - np.count_nonzero(
                (idents >= 48) & (idents <= 57)):
            return None
        sig = self.lut[idents]
        vals = first[is_val] - 48
        t_end = nl[is_time]
        t_before = reader.t

        def time_at(pos: np.ndarray[Any, Any]) -> list[int]:
            """The times of the value changes at bytes ``pos`` (the last ``#`` before each)."""
            ks = (np.searchsorted(t_pos, pos) - 1).tolist()
            return [t_before if k < 0 else int(chunk[t_pos[k] + 1:t_end[k]]) for k in ks]

        out: list[tuple[int, Record]] = []
        for number, ch in enumerate(self.chans):
            out += _channel(ch, [np.flatnonzero(sig == number * 4 + role) for role in range(4)],
                            vals, v_pos, time_at, reader)
        if len(t_pos):
            reader.t = int(chunk[t_pos[-1] + 1:t_end[-1]])
        out.sort(key=lambda item: item[0])
        return [record for _, record in out]


def _level_at(changes: np.ndarray[Any, Any], vals: np.ndarray[Any, Any],
              at: np.ndarray[Any, Any], init: int) -> np.ndarray[Any, Any]:
    """The level of a line (changing at ``changes``) just before each index of ``at``."""
    last = np.searchsorted(changes, at) - 1
    if len(changes) == 0:
        return np.full(len(at), init, dtype=np.uint8)
    return np.where(last >= 0, vals[changes][np.maximum(last, 0)], init).astype(np.uint8)


def _bits_of(value: int, n: int, msb: bool) -> list[int]:
    return [(value >> (n - 1 - i)) & 1 for i in range(n)] if msb else \
        [(value >> i) & 1 for i in range(n)]


def _channel(ch: Chan, by_role: list[np.ndarray[Any, Any]], vals: np.ndarray[Any, Any],
             lines: np.ndarray[Any, Any],
             time_at: Callable[[np.ndarray[Any, Any]], list[int]], reader: ReaderState
             ) -> list[tuple[int, Record]]:
    """The transfers of one channel; ``by_role``: the indices (into ``vals``/``lines``) of its
    CS, CLK, MOSI and MISO changes, each line worked on as its own subsequence."""
    cs_i, clk_i, mo_i, mi_i = by_role
    if not (len(cs_i) or len(clk_i) or len(mo_i) or len(mi_i)):
        return []
    cs_v = vals[cs_i]
    edge = cs_v != np.concatenate(([ch.cs], cs_v[:-1]))
    edge_i, edge_fall = cs_i[edge], cs_v[edge] == 0
    fall_i = edge_i[edge_fall]
    samples = _Samples.take(ch, by_role, vals, edge_i, edge_fall, reader)
    out: list[tuple[int, Record]] = []
    before = np.concatenate(([ch.active], edge_fall[:-1]))  # active before each edge
    fall_t = [ch.t0, *time_at(lines[fall_i])]  # start time of transfer k
    rises = edge_i[~edge_fall & before]
    for line, seg in zip(lines[rises].tolist(), np.searchsorted(fall_i, rises).tolist(),
                         strict=True):
        mo_b, mi_b, _, _ = samples.segment(ch, seg)
        start = fall_t[seg] * reader.scale
        out += [(line, Record(start, route.direction, mo_b if route.line == "mosi" else mi_b))
                for route in ch.routes]
    ch.t0 = fall_t[-1]
    end_active = bool(edge_fall[-1]) if len(edge_i) else ch.active
    if end_active:
        _keep_open(ch, samples.segment(ch, len(fall_i)), reader.msb)
    else:
        ch.nbits = ch.mo = ch.mi = 0
        ch.mosi_bytes.clear()
        ch.miso_bytes.clear()
    _keep_levels(ch, by_role, vals)
    ch.active = end_active
    return out


_Segment = tuple[bytes, bytes, np.ndarray[Any, Any], np.ndarray[Any, Any]]


class _Samples:
    """The MOSI and MISO levels at a channel's sampling clock edges while chip select is low,
    grouped by transfer: those of transfer k (0: the one open before this chunk) are
    ``mosi[at[k]:at[k + 1]]``."""

    def __init__(self, mosi: np.ndarray[Any, Any], miso: np.ndarray[Any, Any], at: list[int],
                 msb: bool) -> None:
        self.mosi, self.miso, self.at, self.msb = mosi, miso, at, msb

    @classmethod
    def take(cls, ch: Chan, by_role: list[np.ndarray[Any, Any]], vals: np.ndarray[Any, Any],
             edge_i: np.ndarray[Any, Any], edge_fall: np.ndarray[Any, Any],
             reader: ReaderState) -> _Samples:
        _, clk_i, mo_i, mi_i = by_role
        clk_v = vals[clk_i]
        clk_prev = np.concatenate(([ch.clk], clk_v[:-1]))
        cand = clk_i[(clk_v != clk_prev) & (clk_v == reader.sample_level)]
        last_edge = np.searchsorted(edge_i, cand) - 1  # the last chip select edge before it
        active = np.where(last_edge >= 0,
                          edge_fall[np.maximum(last_edge, 0)] if len(edge_i) else False,
                          ch.active)
        s_idx = cand[active]
        fall_i = edge_i[edge_fall]
        s_seg = np.searchsorted(fall_i, s_idx)  # 0: the transfer open before this chunk
        at = np.searchsorted(s_seg, np.arange(len(fall_i) + 2)).tolist()
        return cls(_level_at(mo_i, vals, s_idx, ch.mosi), _level_at(mi_i, vals, s_idx, ch.miso),
                   at, reader.msb)

    def segment(self, ch: Chan, seg: int) -> _Segment:
        """Transfer ``seg``'s whole bytes on MOSI and MISO, and the bits left over."""
        lo, hi = self.at[seg], self.at[seg + 1]
        mo, mi = self.mosi[lo:hi], self.miso[lo:hi]
        head_mo = head_mi = b""
        if seg == 0:  # the transfer open before this chunk
            head_mo, head_mi = bytes(ch.mosi_bytes), bytes(ch.miso_bytes)
            mo = np.concatenate((np.array(_bits_of(ch.mo, ch.nbits, self.msb), np.uint8), mo))
            mi = np.concatenate((np.array(_bits_of(ch.mi, ch.nbits, self.msb), np.uint8), mi))
        if len(head_mo) + len(mo) // 8 > MAX_TRANSFER:
            raise InputError(f"transfer longer than {MAX_TRANSFER} bytes (chip select "
                             "never rises?)")
        whole = len(mo) - len(mo) % 8
        order: Literal["big", "little"] = "big" if self.msb else "little"
        return (head_mo + np.packbits(mo[:whole], bitorder=order).tobytes(),
                head_mi + np.packbits(mi[:whole], bitorder=order).tobytes(),
                mo[whole:], mi[whole:])


def _keep_open(ch: Chan, segment: _Segment, msb: bool) -> None:
    """Carry the transfer still open at the end of the chunk in the channel's state."""
    mo_b, mi_b, rest_mo, rest_mi = segment
    ch.mosi_bytes, ch.miso_bytes = bytearray(mo_b), bytearray(mi_b)
    ch.nbits = len(rest_mo)
    ch.mo = ch.mi = 0
    for bit in range(ch.nbits):
        if msb:
            ch.mo, ch.mi = (ch.mo << 1) | int(rest_mo[bit]), (ch.mi << 1) | int(rest_mi[bit])
        else:
            ch.mo |= int(rest_mo[bit]) << bit
            ch.mi |= int(rest_mi[bit]) << bit


def _keep_levels(ch: Chan, by_role: list[np.ndarray[Any, Any]],
                 vals: np.ndarray[Any, Any]) -> None:
    """Each line's last level in the chunk, for the next chunk to start from."""
    cs_i, clk_i, mo_i, mi_i = by_role
    if len(cs_i):
        ch.cs = int(vals[cs_i[-1]])
    if len(clk_i):
        ch.clk = int(vals[clk_i[-1]])
    if len(mo_i):
        ch.mosi = int(vals[mo_i[-1]])
    if len(mi_i):
        ch.miso = int(vals[mi_i[-1]])


def read_vcd(src: ByteSource, opts: SpiOptions, *, chunk_size: int = 1 << 20
             ) -> Iterator[Record]:
    """The VCD reader with :class:`FastPath` on every chunk it can take (the reference's token
    loop reads the rest)."""
    return vcd_records(src, opts, chunk_size, FastPath.build)
