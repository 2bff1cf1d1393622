"""What the VCD reader's reference (:mod:`eyeq_spi.logic.vcd_ref`, the token loop) and fast
twin (:mod:`eyeq_spi.logic.vcd_fast`, numpy) share: the SPI roles of a signal, one channel's
decoding state (both paths advance the same objects, so they can take turns chunk by chunk) and
the reader state the fast twin reads and advances."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Protocol

from eyeq_spi.capture.pcapng_io import Record
from eyeq_spi.logic.options import Route

CS, CLK, MOSI, MISO = range(4)


class Chan:
    """One SPI channel: its line levels, the transfer being shifted in, its routes."""

    __slots__ = ("active", "clk", "cs", "mi", "miso", "miso_bytes", "mo", "mosi", "mosi_bytes",
                 "name", "nbits", "routes", "t0")

    def __init__(self, name: str, routes: list[Route]) -> None:
        self.name = name
        self.routes = routes
        self.cs = 1
        self.clk = -1
        self.mosi = self.miso = 0
        self.active = False
        self.nbits = self.mo = self.mi = 0
        self.mosi_bytes = bytearray()
        self.miso_bytes = bytearray()
        self.t0 = 0

    def emit(self, time: float) -> Iterator[Record]:
        for r in self.routes:
            data = self.mosi_bytes if r.line == "mosi" else self.miso_bytes
            yield Record(time, r.direction, bytes(data))


class ReaderState(Protocol):
    """The reader's clock and sampling settings."""

    t: int  # the last ``#time`` read, in timescale units
    scale: float  # seconds per timescale unit
    sample_level: int  # the clock level after the sampling edge
    msb: bool  # bits arrive most significant first


class ChunkPath(Protocol):
    """A fast twin's reader of one chunk: the records, or the length of a head for the token
    loop to read first, or None when the token loop must read it all."""

    def run(self, reader: ReaderState, chunk: bytes) -> list[Record] | int | None: ...


ChunkPathBuilder = Callable[[dict[bytes, list[tuple[Chan, int]]]], "ChunkPath | None"]
