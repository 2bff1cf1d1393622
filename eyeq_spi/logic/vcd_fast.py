"""The vectorised path of the VCD reader (numpy), for the common shape of a VCD body: one value
change or ``#time`` per line, one-character identifiers, plain ``0``/``1`` values. It computes
exactly what the token loop of :mod:`eyeq_spi.logic.vcd` computes (a property test compares
them on random waveforms cut at random places) and returns None for any chunk it cannot take,
which the token loop then reads.

Per SPI channel: the level of every line after each change is a forward fill; chip select
falling/rising edges split the sampling clock edges into transfers; bits are packed with
``numpy.packbits``. The open transfer at the end of a chunk is carried in the channel's state.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from eyeq_spi.capture.pcapng_io import Record
from eyeq_spi.logic.options import MAX_TRANSFER, LogicInputError

if TYPE_CHECKING:
    from eyeq_spi.logic.vcd import _Chan, _Reader

CS, CLK, MOSI, MISO = range(4)
_IGNORED = -1


class FastPath:
    def __init__(self, lut: np.ndarray[Any, Any], chans: list[_Chan]) -> None:
        self.lut = lut  # identifier byte -> channel * 4 + role, or -1
        self.chans = chans

    @classmethod
    def build(cls, table: dict[bytes, list[tuple[_Chan, int]]]) -> FastPath | None:
        lut = np.full(256, _IGNORED, dtype=np.int64)
        chans: list[_Chan] = []
        for ident, targets in table.items():
            if len(ident) != 1 or len(targets) != 1:
                return None  # longer identifiers or a line feeding two roles: token loop
            ch, role = targets[0]
            if ch not in chans:
                chans.append(ch)
            lut[ident[0]] = chans.index(ch) * 4 + role
        return cls(lut, chans)

    def run(self, reader: _Reader, chunk: bytes) -> list[Record] | int | None:
        """The records of ``chunk``; or the length of a head of it (up to the last line this
        path cannot take, in its first half: ``$dumpvars``...) for the token loop to read
        first; or None when the token loop must read it all."""
        if not chunk.endswith(b"\n"):
            return None
        raw = np.frombuffer(chunk, dtype=np.uint8)
        nl = np.flatnonzero(raw == 10)
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
        if len(t_pos):
            # every time is digits only (else the token loop reports it), parsed on demand
            bounds = np.empty(2 * len(t_pos), dtype=np.int64)
            bounds[0::2], bounds[1::2] = t_pos + 1, nl[is_time]
            if np.logical_or.reduceat((raw - 48) > 9, bounds)[0::2].any():
                return None
        v_pos = starts[is_val]
        sig = self.lut[raw[v_pos + 1]]
        vals = (first[is_val] - 48).astype(np.int64)
        t_end = nl[is_time]
        t_before = reader.t

        def time_at(pos: int) -> int:
            """The time of the value change at byte ``pos`` (the last ``#`` line before)."""
            k = int(np.searchsorted(t_pos, pos)) - 1
            return t_before if k < 0 else int(chunk[t_pos[k] + 1:t_end[k]])

        out: list[tuple[int, Record]] = []
        for c, ch in enumerate(self.chans):
            sel = (sig >> 2) == c
            sel &= sig >= 0
            out += _channel(ch, sig[sel] & 3, vals[sel], v_pos[sel], time_at, reader)
        if len(t_pos):
            reader.t = int(chunk[t_pos[-1] + 1:t_end[-1]])
        out.sort(key=lambda x: x[0])
        return [r for _, r in out]


def _ffill(mask: np.ndarray[Any, Any], vals: np.ndarray[Any, Any], init: int
           ) -> np.ndarray[Any, Any]:
    idx = np.maximum.accumulate(np.where(mask, np.arange(len(mask)), -1))
    return np.where(idx >= 0, vals[np.maximum(idx, 0)], init)


def _bits_of(value: int, n: int, msb: bool) -> list[int]:
    return [(value >> (n - 1 - i)) & 1 for i in range(n)] if msb else \
        [(value >> i) & 1 for i in range(n)]


def _channel(ch: _Chan, roles: np.ndarray[Any, Any], vals: np.ndarray[Any, Any],
             lines: np.ndarray[Any, Any], time_at: Callable[[int], int], reader: _Reader
             ) -> list[tuple[int, Record]]:
    n = len(roles)
    if n == 0:
        return []
    msb = reader.msb
    is_cs = roles == CS
    cs_lvl = _ffill(is_cs, vals, ch.cs)
    cs_prev = np.concatenate(([ch.cs], cs_lvl[:-1]))
    fall = is_cs & (cs_prev == 1) & (vals == 0)
    rise = is_cs & (cs_prev == 0) & (vals == 1)
    edges = fall | rise
    act_idx = np.maximum.accumulate(np.where(edges, np.arange(n), -1))
    active = np.where(act_idx >= 0, fall[np.maximum(act_idx, 0)], ch.active)
    active_before = np.concatenate(([ch.active], active[:-1]))
    is_clk = roles == CLK
    clk_lvl = _ffill(is_clk, vals, ch.clk)
    clk_prev = np.concatenate(([ch.clk], clk_lvl[:-1]))
    sample = is_clk & (vals != clk_prev) & (vals == reader.sample_level) & active
    mo_lvl = _ffill(roles == MOSI, vals, ch.mosi)
    mi_lvl = _ffill(roles == MISO, vals, ch.miso)
    seg = np.cumsum(fall)
    s_idx = np.flatnonzero(sample)
    s_seg = seg[s_idx]
    s_mo = mo_lvl[s_idx].astype(np.uint8)
    s_mi = mi_lvl[s_idx].astype(np.uint8)
    fall_idx = np.flatnonzero(fall)
    order: Literal["big", "little"] = "big" if msb else "little"

    def segment(k: int) -> tuple[bytes, bytes, np.ndarray[Any, Any], np.ndarray[Any, Any]]:
        lo, hi = np.searchsorted(s_seg, k, "left"), np.searchsorted(s_seg, k, "right")
        mo, mi = s_mo[lo:hi], s_mi[lo:hi]
        head_mo = head_mi = b""
        if k == 0:  # the transfer open before this chunk
            head_mo, head_mi = bytes(ch.mosi_bytes), bytes(ch.miso_bytes)
            mo = np.concatenate((np.array(_bits_of(ch.mo, ch.nbits, msb), np.uint8), mo))
            mi = np.concatenate((np.array(_bits_of(ch.mi, ch.nbits, msb), np.uint8), mi))
        if len(head_mo) + len(mo) // 8 > MAX_TRANSFER:
            raise LogicInputError(f"transfer longer than {MAX_TRANSFER} bytes (chip select "
                                  "never rises?)")
        whole = len(mo) - len(mo) % 8
        return (head_mo + np.packbits(mo[:whole], bitorder=order).tobytes(),
                head_mi + np.packbits(mi[:whole], bitorder=order).tobytes(),
                mo[whole:], mi[whole:])

    out: list[tuple[int, Record]] = []
    for e in np.flatnonzero(rise & active_before):
        k = int(seg[e])
        t0 = ch.t0 if k == 0 else time_at(int(lines[fall_idx[k - 1]]))
        mo_b, mi_b, _, _ = segment(k)
        for r in ch.routes:
            out.append((int(lines[e]), Record(t0 * reader.scale, r.direction,
                                              mo_b if r.line == "mosi" else mi_b)))
    last = int(seg[-1])
    if last > 0:
        ch.t0 = time_at(int(lines[fall_idx[last - 1]]))
    if bool(active[-1]):
        mo_b, mi_b, rest_mo, rest_mi = segment(last)
        ch.mosi_bytes, ch.miso_bytes = bytearray(mo_b), bytearray(mi_b)
        ch.nbits = len(rest_mo)
        ch.mo = ch.mi = 0
        for i in range(ch.nbits):
            if msb:
                ch.mo, ch.mi = (ch.mo << 1) | int(rest_mo[i]), (ch.mi << 1) | int(rest_mi[i])
            else:
                ch.mo |= int(rest_mo[i]) << i
                ch.mi |= int(rest_mi[i]) << i
    else:
        ch.nbits = ch.mo = ch.mi = 0
        ch.mosi_bytes.clear()
        ch.miso_bytes.clear()
    ch.cs, ch.clk = int(cs_lvl[-1]), int(clk_lvl[-1])
    ch.mosi, ch.miso = int(mo_lvl[-1]), int(mi_lvl[-1])
    ch.active = bool(active[-1])
    return out

