"""Transfers -> a sigrok session file (``.sr``, what PulseView saves and opens;
``eyeq-spi export --sr``).

A session file is a zip archive (libsigrok's ``srzip``, version 2): ``version``, an ini
``metadata`` (sample rate, probes, ``unitsize``) and deflated sample entries ``logic-1-1``...
One sample is one byte: bit k is probe k + 1, the four signals of each SPI channel (§5) in the
order of ``specs/bench.yaml``. The waveforms are those of :mod:`eyeq_spi.logic.vcd_write`, at
two samples per clock period (20 MHz for 10 MHz), starting ``LEAD`` samples before the first
transfer; MOSI returns low when CS rises. Samples are rendered per transfer into a buffer
written out in ``CHUNK``-byte pieces (bounded memory); ``max_idle`` shortens every stretch with
both channels idle (sample times are then not capture times; the metadata says so).
"""

from __future__ import annotations

import zipfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from eyeq_spi import __version__
from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.logic.options import DIRECTIONS, SIGNALS, SpiOptions, bench_spec, signal_name
from eyeq_spi.logic.vcd_write import Timeline, frame_bits

CHUNK = 4 << 20  # samples (bytes) per logic-1-N entry
SAMPLES_PER_HALF_CLOCK = 1
LEAD = 20  # idle samples before the first transfer (1 µs at 20 MHz): its CS edge shows
_Array = np.ndarray[Any, Any]


def _bit(direction: str, signal: str) -> int:
    return DIRECTIONS.index(direction) * len(SIGNALS) + SIGNALS.index(signal)


def samplerate_text(hz: int) -> str:
    """libsigrok's way of writing a sample rate (``20 MHz``, ``500 kHz``)."""
    for unit, scale in (("GHz", 10**9), ("MHz", 10**6), ("kHz", 10**3)):
        if hz >= scale and hz % scale == 0:
            return f"{hz // scale} {unit}"
    return f"{hz} Hz"


class _ChunkSink:
    """Samples in, ``logic-1-N`` entries of at most CHUNK bytes out."""

    def __init__(self, zf: zipfile.ZipFile) -> None:
        self.zf = zf
        self.buf = bytearray()
        self.entries = 0
        self.samples = 0
        self._block: tuple[int, bytes] | None = None

    def array(self, samples: _Array) -> None:
        self.samples += len(samples)
        self.buf += samples.tobytes()
        while len(self.buf) >= CHUNK:
            self._entry(bytes(self.buf[:CHUNK]))
            del self.buf[:CHUNK]

    def run(self, value: int, count: int) -> None:
        """``count`` samples of ``value`` (an idle stretch), without building them all."""
        if self._block is None or self._block[0] != value:
            self._block = (value, bytes([value]) * CHUNK)
        block = self._block[1]
        self.samples += count
        room = CHUNK - len(self.buf)
        if count < room:
            self.buf += block[:count]
            return
        self.buf += block[:room]
        self._entry(bytes(self.buf))
        self.buf.clear()
        count -= room
        while count >= CHUNK:
            self._entry(block)
            count -= CHUNK
        self.buf += block[:count]

    def close(self) -> None:
        if self.buf or not self.entries:
            self._entry(bytes(self.buf))
            self.buf.clear()

    def _entry(self, data: bytes) -> None:
        self.entries += 1
        self.zf.writestr(f"logic-1-{self.entries}", data, compress_type=zipfile.ZIP_DEFLATED,
                         compresslevel=6)


class SrWriter(Timeline):
    """Write transfers (:meth:`write`) into the session file at ``path``; :meth:`close` ends it."""

    def __init__(self, path: str | Path, opts: SpiOptions | None = None, *,
                 baud_rate: int | None = None, default_direction: str = "h2e",
                 max_idle: float | None = None) -> None:
        spec = bench_spec()
        self.opts = opts or SpiOptions()
        baud = baud_rate or int(spec["spi"]["baud_rate"])
        self.half = SAMPLES_PER_HALF_CLOCK
        self.samplerate = 2 * baud * self.half
        super().__init__(lambda seconds: round(seconds * self.samplerate), max_idle, LEAD)
        self.cpol, self.cpha = divmod(self.opts.mode, 2)
        self.default_direction = default_direction
        idle_miso = int(spec["vcd"]["idle_miso"])
        self.idle = 0
        for direction in DIRECTIONS:
            self.idle |= (1 << _bit(direction, "cs")) | (self.cpol << _bit(direction, "clk"))
            self.idle |= idle_miso << _bit(direction, "miso")
        self.origin: float | None = None  # the first capture time: sample LEAD
        self.cursor = 0  # samples before this one are written
        self.pending = np.empty(0, dtype=np.uint8)  # samples from the cursor on, still open
        self.closed = False
        self.zf = zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED)
        self.zf.writestr("version", "2")
        self.sink = _ChunkSink(self.zf)

    def write(self, transfer: Transfer) -> None:
        direction = transfer.direction or self.default_direction
        at = None
        if transfer.time is not None:
            if self.origin is None:
                self.origin = transfer.time
            at = round((transfer.time - self.origin) * self.samplerate) + LEAD
        wanted = self.wanted(direction, at, self.cursor + len(self.pending))
        self._flush(wanted)  # no later transfer starts before its capture time
        start = self.start(direction, wanted, self.cursor, at is not None)
        lines = self._transfer(direction, transfer.data)
        end = start + len(lines)
        self._extend(end)
        offset = start - self.cursor
        mask = np.uint8(sum(1 << _bit(direction, s) for s in ("cs", "clk", "mosi")))
        window = self.pending[offset:offset + len(lines)]
        window &= ~mask
        window |= lines
        self.end(direction, end)

    def _transfer(self, direction: str, data: bytes) -> _Array:
        """The channel's CS, CLK and MOSI bits of one transfer, from CS falling to the sample
        before CS rises (the frame of :class:`eyeq_spi.logic.vcd_write.VcdWriter`)."""
        h = self.half
        bits = frame_bits(data, self.opts.bit_order)
        count = len(bits)
        t = 0 if self.cpha else h  # the first bit's period begins here
        length = t + 2 * h * count + h
        rel = np.arange(length) - t  # samples since the first bit's period began
        bit_no = np.clip((rel - (h if self.cpha else 0)) // (2 * h), -1, count - 1)
        mosi = np.where(bit_no >= 0, bits[np.maximum(bit_no, 0)] if count else 0, 0)
        in_bits = (rel >= h) & (rel < h + 2 * h * count)
        clk = np.where(in_bits & (((rel - h) % (2 * h)) < h), 1 - self.cpol, self.cpol)
        out = (clk.astype(np.uint8) << _bit(direction, "clk")) | (mosi.astype(np.uint8)
                                                          << _bit(direction, "mosi"))
        return out.astype(np.uint8)  # CS (its bit 0) low throughout

    def _extend(self, end: int) -> None:
        more = end - self.cursor - len(self.pending)
        if more > 0:
            self.pending = np.concatenate((self.pending,
                                           np.full(more, self.idle, dtype=np.uint8)))

    def _flush(self, limit: int) -> None:
        """Write every sample before ``limit``."""
        if limit <= self.cursor:
            return
        take = min(limit - self.cursor, len(self.pending))
        if take:
            self.sink.array(self.pending[:take])
            self.pending = self.pending[take:]
        if limit - self.cursor > take:
            self.sink.run(self.idle, limit - self.cursor - take)
        self.cursor = limit

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        # two idle samples after the last change, so a reader sees the last CS rising edge
        self._flush(self.cursor + len(self.pending) + 2)
        self.sink.close()
        self.zf.writestr("metadata", self._metadata())
        self.zf.close()

    def _metadata(self) -> str:
        probes = [signal_name(d, s) for d in DIRECTIONS for s in SIGNALS]
        lines = ["[global]", f"sigrok version={__version__} (eyeq-spi)"]
        if self.max_idle is not None:  # a GLib key file's comment line starts with #
            lines.append(f"# idle time compressed: every stretch with both channels idle is at "
                         f"most {self.max_idle / self.samplerate:g} s; times are not capture "
                         "times")
        lines += ["", "[device 1]", "capturefile=logic-1", f"total probes={len(probes)}",
                  f"samplerate={samplerate_text(self.samplerate)}", "total analog=0"]
        lines += [f"probe{k}={name}" for k, name in enumerate(probes, start=1)]
        lines.append("unitsize=1")
        return "\n".join(lines) + "\n"


def write_sr(transfers: Iterable[Transfer], path: str | Path, opts: SpiOptions | None = None,
             **kw: Any) -> SrWriter:
    writer = SrWriter(path, opts, **kw)
    try:
        for transfer in transfers:
            writer.write(transfer)
    finally:
        writer.close()
    return writer


def write_sr_file(transfers: Iterable[Transfer], path: str | Path, **options: Any) -> int:
    """The io registry's capture-writer signature: ``options`` are :class:`SrWriter`'s keyword
    arguments, ``opts`` the SPI options; returns the transfers written."""
    return write_sr(transfers, path, options.pop("opts", None), **options).count
