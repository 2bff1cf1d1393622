"""The VCD reader's vocabulary (:mod:`eyeq_spi.logic.vcd`): the SPI roles of a signal and one
channel's decoding state."""

from __future__ import annotations

from collections.abc import Iterator

from eyeq_spi.capture.pcapng_io import Transfer
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

    def emit(self, time: float) -> Iterator[Transfer]:
        for route in self.routes:
            data = self.mosi_bytes if route.line == "mosi" else self.miso_bytes
            yield Transfer(time, route.direction, bytes(data))
