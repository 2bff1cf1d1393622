"""Transfers -> VCD waveforms of the two SPI channels (``eyeq-spi export --vcd``), for PulseView
and sigrok, readable again by :mod:`eyeq_spi.logic.vcd`.

Each direction is one SPI channel with CS, CLK, MOSI and MISO (§5); its master drives the frame
on MOSI at the seed's 10 MHz in mode 1 (§6 driver settings), most significant bit first
(``specs/bench.yaml``). A transfer starts at its capture time; one without a time (raw or hex
input) starts the channel's frameFlowControl (§6: 500 µs host, 200 µs EyeQ) after the previous
one, as the link paces them (L7); one that would overlap the previous transfer of its channel
starts ``min_idle`` after its CS rising edge (``specs/bench.yaml``). The slave's MISO is left
idle. Memory stays bounded: only the transfers that still overlap the next capture time are
held.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Iterable
from typing import IO

from eyeq_spi import __version__
from eyeq_spi.capture.pcapng_io import Record
from eyeq_spi.logic.options import DIRECTIONS, SIGNALS, SpiOptions, bench_spec, signal_name
from eyeq_spi.spec.link import link_spec

_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "ps": 1e-12}
_SENDER = {"h2e": "host", "e2h": "eyeq"}


def _timescale(text: str) -> float:
    num = text.rstrip("smunpf")
    return int(num) * _UNITS[text[len(num):]]


class VcdWriter:
    def __init__(self, fh: IO[str], opts: SpiOptions | None = None, *,
                 baud_rate: int | None = None, timescale: str | None = None,
                 default_direction: str = "h2e") -> None:
        spec = bench_spec()
        self.fh = fh
        self.opts = opts or SpiOptions()
        self.timescale = timescale or str(spec["vcd"]["timescale"])
        self.scale = _timescale(self.timescale)
        baud = baud_rate or int(spec["spi"]["baud_rate"])
        self.half = max(1, round(1 / (2 * baud) / self.scale))
        gaps = link_spec()["timing"]["frameFlowControl"]
        self.gap = {d: round(float(gaps[_SENDER[d]]) / self.scale) for d in DIRECTIONS}
        self.min_idle = max(1, round(float(spec["vcd"]["min_idle"]) / self.scale))
        self.last_start = dict.fromkeys(DIRECTIONS, -(10**18))
        self.default_direction = default_direction
        self.free = dict.fromkeys(DIRECTIONS, 0)
        self.ids = {d: {s: chr(ord("a") + 4 * i + j) for j, s in enumerate(SIGNALS)}
                    for i, d in enumerate(DIRECTIONS)}
        self.cpol, self.cpha = divmod(self.opts.mode, 2)
        self.level = {d: 0 for d in DIRECTIONS}  # MOSI level
        self.pending: list[list[tuple[int, str]]] = []
        self.last_tick = -1
        self.count = 0
        self.delayed = 0
        self._templates: dict[tuple[str, int, int], tuple[list[tuple[int, str]], int]] = {}
        self._header()

    def _header(self) -> None:
        w = self.fh.write
        w(f"$date {_dt.datetime.now(_dt.UTC).isoformat(timespec='seconds')} $end\n")
        w(f"$version eyeq-spi {__version__} $end\n")
        w(f"$comment EyeQ4 SPI, two channels (seed 004 §5), mode {self.opts.mode}, "
          f"{self.opts.bit_order} $end\n")
        w(f"$timescale {self.timescale} $end\n$scope module eyeq_spi $end\n")
        for d in DIRECTIONS:
            for s in SIGNALS:
                w(f"$var wire 1 {self.ids[d][s]} {signal_name(d, s)} $end\n")
        w("$upscope $end\n$enddefinitions $end\n#0\n$dumpvars\n")
        idle_miso = int(bench_spec()["vcd"]["idle_miso"])
        for d in DIRECTIONS:
            i = self.ids[d]
            w(f"1{i['cs']}\n{self.cpol}{i['clk']}\n0{i['mosi']}\n{idle_miso}{i['miso']}\n")
        w("$end\n")
        self.last_tick = 0

    def _byte(self, d: str, value: int, level: int) -> tuple[list[tuple[int, str]], int]:
        """Events of one byte relative to its first bit's leading edge minus a half period."""
        key = (d, value, level)
        hit = self._templates.get(key)
        if hit is not None:
            return hit
        h, ids = self.half, self.ids[d]
        lead, trail = 1 - self.cpol, self.cpol
        ev: list[tuple[int, str]] = []
        bits = range(7, -1, -1) if self.opts.bit_order == "msb_first" else range(8)
        for k, b in enumerate(bits):
            bit = (value >> b) & 1
            base = 2 * h * k
            set_at = base + h if self.cpha else base  # CPHA 1: on the leading edge
            if bit != level:
                ev.append((set_at, f"{bit}{ids['mosi']}"))
                level = bit
            ev.append((base + h, f"{lead}{ids['clk']}"))
            ev.append((base + 2 * h, f"{trail}{ids['clk']}"))
        self._templates[key] = (ev, level)
        return ev, level

    def write(self, rec: Record) -> None:
        d = rec.direction or self.default_direction
        if rec.time is None:
            ticks = max(self.free[d], self.last_start[d] + self.gap[d], self.last_tick + 1)
        else:
            ticks = round(rec.time / self.scale)
        self._flush(ticks)
        start = max(ticks, self.free[d], self.last_tick + 1)
        self.last_start[d] = start
        if start > ticks and rec.time is not None:
            self.delayed += 1
        ids, h = self.ids[d], self.half
        ev: list[tuple[int, str]] = [(start, f"0{ids['cs']}")]
        t = start + (0 if self.cpha else h)
        level = self.level[d]
        for value in rec.data:
            rel, level = self._byte(d, value, level)
            ev += [(t + off, line) for off, line in rel]
            t += 16 * h
        end = t + h
        ev.append((end, f"1{ids['cs']}"))
        self.level[d] = level
        self.free[d] = end + self.min_idle
        self.pending.append(ev)
        self.count += 1

    def _flush(self, limit: int | None) -> None:
        """Write every pending event before ``limit`` (all of them when None)."""
        if not self.pending:
            return
        out: list[tuple[int, str]] = []
        keep: list[list[tuple[int, str]]] = []
        blocks = 0
        for ev in self.pending:
            if limit is None or ev[-1][0] < limit:
                out += ev
                blocks += 1
            else:
                n = next(i for i, e in enumerate(ev) if e[0] >= limit)
                out += ev[:n]
                blocks += n > 0
                keep.append(ev[n:])
        self.pending = keep
        if blocks > 1:
            out.sort(key=lambda e: e[0])  # stable: a channel's events keep their order
        lines: list[str] = []
        last = self.last_tick
        for tick, line in out:
            if tick != last:
                lines.append(f"#{tick}")
                last = tick
            lines.append(line)
        if lines:
            lines.append("")
            self.fh.write("\n".join(lines))
        self.last_tick = last

    def close(self) -> None:
        self._flush(None)
        # a last timestamp after the last change, or readers that turn changes into samples
        # (libsigrok) never see the last CS rising edge
        self.last_tick += 2 * self.half
        self.fh.write(f"#{self.last_tick}\n")


def write_vcd(records: Iterable[Record], fh: IO[str], opts: SpiOptions | None = None,
              **kw: object) -> VcdWriter:
    w = VcdWriter(fh, opts, **kw)  # type: ignore[arg-type]
    for rec in records:
        w.write(rec)
    w.close()
    return w
