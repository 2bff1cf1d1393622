"""Transfers -> VCD waveforms of the two SPI channels (``eyeq-spi export --vcd``), for PulseView
and sigrok, readable again by :mod:`eyeq_spi.logic.vcd`.

Each direction is one SPI channel with CS, CLK, MOSI and MISO (§5); its master drives the frame
on MOSI at the seed's 10 MHz in mode 1 (§6), most significant bit first (``specs/bench.yaml``).
A transfer starts at its capture time; one without a time starts the channel's frameFlowControl
(§6, L7) after the previous one; one that would overlap the previous transfer of its channel
starts ``min_idle`` after its CS rising edge. The slave's MISO is left idle. The file grows
with the bits sent (:func:`estimate_size`); ``max_idle`` shortens every stretch with both
channels idle, which the file says in a ``$comment``.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable, Iterable
from typing import IO, Any, Literal

import numpy as np

from eyeq_spi import __version__
from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.catalog.link import link_spec
from eyeq_spi.logic.options import DIRECTIONS, SIGNALS, SpiOptions, bench_spec, signal_name

_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "ps": 1e-12}
_SENDER = {"h2e": "host", "e2h": "eyeq"}


def _timescale(text: str) -> float:
    num = text.rstrip("smunpf")
    return int(num) * _UNITS[text[len(num):]]


def estimate_size(transfers: int, data_bytes: int, span_s: float,
                  timescale: str | None = None) -> int:
    """About how many bytes :class:`VcdWriter` writes for ``transfers`` transfers of
    ``data_bytes`` bytes in all over ``span_s`` seconds: per bit two clock edges (a timestamp
    line and a value line each) and half a MOSI change, plus a line per CS edge."""
    scale = _timescale(timescale or str(bench_spec()["vcd"]["timescale"]))
    digits = len(str(max(1, round(span_s / scale))))
    per_bit = 2 * (digits + 2) + 2 * 3 + 0.5 * 3
    return int(512 + data_bytes * 8 * per_bit + transfers * 2 * (digits + 5))


class Timeline:
    """Where each transfer of a waveform starts, in ticks (VCD) or samples (sigrok): at its
    capture time; without one, its channel's frameFlowControl (§6, L7) after the channel's
    previous start; never before the channel's previous transfer ended plus ``min_idle``. A
    stretch with both channels idle longer than ``max_idle`` is cut to it (``shift``: ticks cut
    so far); ``delayed`` counts the transfers moved off their capture time."""

    def __init__(self, to_ticks: Callable[[float], int], max_idle: float | None,
                 first: int = 0) -> None:
        gaps = link_spec()["timing"]["frameFlowControl"]
        self.gap = {d: to_ticks(float(gaps[_SENDER[d]])) for d in DIRECTIONS}
        self.min_idle = max(1, to_ticks(float(bench_spec()["vcd"]["min_idle"])))
        self.max_idle = None if max_idle is None else max(1, to_ticks(max_idle))
        self.free = dict.fromkeys(DIRECTIONS, first)  # the first tick a channel may use next
        self.last_start = dict.fromkeys(DIRECTIONS, -(10**18))
        self.shift = 0
        self.count = 0
        self.delayed = 0

    def wanted(self, direction: str, at: int | None, busy: int) -> int:
        """Where a transfer wants to start: ``at`` (its capture time in ticks; None: it has
        none) with idle time cut; ``busy``: the writer's last tick in use."""
        if at is None:
            return max(self.free[direction], self.last_start[direction] + self.gap[direction])
        wanted = at - self.shift
        if self.max_idle is not None:
            busy_until = max(busy, *self.free.values())
            if wanted - busy_until > self.max_idle:
                self.shift += wanted - busy_until - self.max_idle
                wanted = busy_until + self.max_idle
        return wanted

    def start(self, direction: str, wanted: int, floor: int, timed: bool) -> int:
        """Where it starts: ``wanted``, or later when its channel or the writer (at ``floor``)
        is not free yet."""
        start = max(wanted, self.free[direction], floor)
        self.last_start[direction] = start
        if start > wanted and timed:
            self.delayed += 1
        return start

    def end(self, direction: str, end: int) -> None:
        """The transfer on ``direction`` ends at ``end``."""
        self.free[direction] = end + self.min_idle
        self.count += 1


def frame_bits(data: bytes, bit_order: str) -> np.ndarray[Any, Any]:
    """The bits of ``data`` in the order they are sent."""
    order: Literal["big", "little"] = "big" if bit_order == "msb_first" else "little"
    return np.unpackbits(np.frombuffer(data, dtype=np.uint8), bitorder=order)


class VcdWriter(Timeline):
    def __init__(self, fh: IO[str], opts: SpiOptions | None = None, *,
                 baud_rate: int | None = None, timescale: str | None = None,
                 default_direction: str = "h2e", max_idle: float | None = None) -> None:
        spec = bench_spec()
        self.fh = fh
        self.opts = opts or SpiOptions()
        self.timescale = timescale or str(spec["vcd"]["timescale"])
        self.scale = _timescale(self.timescale)
        super().__init__(lambda seconds: round(seconds / self.scale), max_idle)
        baud = baud_rate or int(spec["spi"]["baud_rate"])
        self.half = max(1, round(1 / (2 * baud) / self.scale))
        self.default_direction = default_direction
        self.ids = {d: {s: chr(ord("a") + 4 * i + j) for j, s in enumerate(SIGNALS)}
                    for i, d in enumerate(DIRECTIONS)}
        self.cpol, self.cpha = divmod(self.opts.mode, 2)
        self.level = {d: 0 for d in DIRECTIONS}  # MOSI level
        self.pending: list[tuple[np.ndarray[Any, Any], np.ndarray[Any, Any]]] = []
        self.last_tick = -1
        self._lines = np.array([f"{v}{self.ids[d][sig]}" for d in DIRECTIONS for sig in SIGNALS
                                for v in (0, 1)], dtype=object)  # indexed by _code()
        self._header()

    def _header(self) -> None:
        write = self.fh.write
        write(f"$date {_dt.datetime.now(_dt.UTC).isoformat(timespec='seconds')} $end\n")
        write(f"$version eyeq-spi {__version__} $end\n")
        write(f"$comment EyeQ4 SPI, two channels (seed 004 §5), mode {self.opts.mode}, "
              f"{self.opts.bit_order} $end\n")
        if self.max_idle is not None:
            write("$comment idle time compressed: every stretch with both channels idle is at "
                  f"most {self.max_idle * self.scale:g} s; times are not capture times $end\n")
        write(f"$timescale {self.timescale} $end\n$scope module eyeq_spi $end\n")
        for direction in DIRECTIONS:
            for signal in SIGNALS:
                write(f"$var wire 1 {self.ids[direction][signal]} {signal_name(direction, signal)} "
                      "$end\n")
        write("$upscope $end\n$enddefinitions $end\n#0\n$dumpvars\n")
        idle_miso = int(bench_spec()["vcd"]["idle_miso"])
        for direction in DIRECTIONS:
            ids = self.ids[direction]
            write(f"1{ids['cs']}\n{self.cpol}{ids['clk']}\n0{ids['mosi']}\n{idle_miso}{ids['miso']}\n")
        write("$end\n")
        self.last_tick = 0

    def _code(self, direction: str, signal: str, value: int) -> int:
        return ((DIRECTIONS.index(direction) * 4 + SIGNALS.index(signal)) << 1) | value

    def write(self, transfer: Transfer) -> None:
        direction = transfer.direction or self.default_direction
        at = None if transfer.time is None else round(transfer.time / self.scale)
        ticks = self.wanted(direction, at, self.last_tick)
        self._flush(ticks)
        start = self.start(direction, ticks, self.last_tick + 1, at is not None)
        h = self.half
        t = start + (0 if self.cpha else h)
        bits = frame_bits(transfer.data, self.opts.bit_order).astype(np.int64)
        count = len(bits)
        base = t + 2 * h * np.arange(count, dtype=np.int64)
        prev = np.concatenate(([self.level[direction]], bits[:-1]))
        change = bits != prev  # MOSI moves only when the bit differs from the line
        set_at = (base + h if self.cpha else base)[change]  # CPHA 1: on the leading edge
        end = t + 2 * h * count + h
        lead, trail = 1 - self.cpol, self.cpol
        times = np.concatenate(([start], set_at, base + h, base + 2 * h, [end]))
        codes = np.concatenate((
            [self._code(direction, "cs", 0)], self._code(direction, "mosi", 0) + bits[change],
            np.full(count, self._code(direction, "clk", lead)),
            np.full(count, self._code(direction, "clk", trail)),
            [self._code(direction, "cs", 1)]))
        by_time = np.argsort(times, kind="stable")
        self.pending.append((times[by_time], codes[by_time]))
        if count:
            self.level[direction] = int(bits[-1])
        self.end(direction, end)

    def _flush(self, limit: int | None) -> None:
        """Write every pending event before ``limit`` (all of them when None)."""
        parts_t, parts_c = [], []
        keep: list[tuple[np.ndarray[Any, Any], np.ndarray[Any, Any]]] = []
        for ticks, codes in self.pending:
            due = len(ticks) if limit is None else int(np.searchsorted(ticks, limit, "left"))
            if due:
                parts_t.append(ticks[:due])
                parts_c.append(codes[:due])
            if due < len(ticks):
                keep.append((ticks[due:], codes[due:]))
        self.pending = keep
        if not parts_t:
            return
        ticks, codes = np.concatenate(parts_t), np.concatenate(parts_c)
        if len(parts_t) > 1:  # two channels overlap: merge, each keeping its own order
            order = np.argsort(ticks, kind="stable")
            ticks, codes = ticks[order], codes[order]
        new = np.empty(len(ticks), dtype=bool)
        new[0] = ticks[0] != self.last_tick
        new[1:] = ticks[1:] != ticks[:-1]
        pos = np.arange(len(ticks)) + np.cumsum(new)
        out = np.empty(len(ticks) + int(new.sum()), dtype=object)
        out[pos] = self._lines[codes]
        out[pos[new] - 1] = list(map("#{}".format, ticks[new].tolist()))
        self.fh.write("\n".join(out.tolist()) + "\n")
        self.last_tick = int(ticks[-1])

    def close(self) -> None:
        self._flush(None)
        # a last timestamp after the last change, or readers that turn changes into samples
        # (libsigrok) never see the last CS rising edge
        self.last_tick += 2 * self.half
        self.fh.write(f"#{self.last_tick}\n")


def write_vcd(transfers: Iterable[Transfer], fh: IO[str], opts: SpiOptions | None = None,
              **kw: object) -> VcdWriter:
    writer = VcdWriter(fh, opts, **kw)  # type: ignore[arg-type]
    for transfer in transfers:
        writer.write(transfer)
    writer.close()
    return writer
