"""How a logic-analyzer capture maps onto the two SPI channels: SPI mode, bit order, signal
names and which channel (and data line) carries ``h2e`` and ``e2h``. Defaults come from
``specs/bench.yaml``."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cache
from typing import Any

from eyeq_spi.capture.pcapng_io import Readable
from eyeq_spi.catalog.link import spec_file
from eyeq_spi.errors import InputError, UsageError

DIRECTIONS = ("h2e", "e2h")
LINES = ("mosi", "miso")
SIGNALS = ("cs", "clk", "mosi", "miso")
MAX_TRANSFER = 4096  # bytes kept per transfer (32 frames); a CS that never rises is an error


@cache
def bench_spec() -> dict[str, Any]:
    return spec_file("bench.yaml")


def whole_chunks(src: Readable, size: int, separators: bytes, limit: int, too_long: str
                 ) -> Iterator[bytes]:
    """The stream in chunks that each end just after one of the ``separators`` (the last one
    may not), in bounded memory: more than ``limit`` bytes without one is an error."""
    rest = b""
    while True:
        data = src.read(size)
        buf = rest + data
        if not data:
            if buf:
                yield buf
            return
        cut = max(buf.rfind(separator) for separator in separators) + 1
        rest = buf[cut:]
        if len(rest) > limit:
            raise InputError(too_long)
        if cut:
            yield buf[:cut]


def sample_on_rising(mode: int) -> bool:
    """SPI modes 0 and 3 sample on the rising clock edge, 1 and 2 on the falling one."""
    return mode in (0, 3)


@dataclass(frozen=True)
class Route:
    direction: str | None
    line: str


@dataclass
class SpiOptions:
    """``mode`` 0..3 (CPOL*2 + CPHA), ``bit_order`` msb_first|lsb_first, ``channel_map``:
    direction -> (channel name or "" for the only channel, line); ``signals``: channel ->
    (cs, clk, mosi, miso or None) VCD signal names; ``direction`` for a single unnamed channel."""

    mode: int = field(default_factory=lambda: int(bench_spec()["spi"]["mode"]))
    bit_order: str = field(default_factory=lambda: str(bench_spec()["spi"]["bit_order"]))
    channel_map: dict[str, tuple[str, str]] = field(default_factory=dict)
    signals: dict[str, tuple[str, str, str, str | None]] = field(default_factory=dict)
    direction: str | None = None

    def __post_init__(self) -> None:
        if self.mode not in (0, 1, 2, 3):
            raise UsageError(f"SPI mode must be 0..3, not {self.mode}")
        if self.bit_order not in ("msb_first", "lsb_first"):
            raise UsageError(f"bit order must be msb_first or lsb_first, not {self.bit_order!r}")

    def routes(self, channel: str, n_channels_hint: int = 1) -> list[Route]:
        """Where the transfers of ``channel`` go. An explicit map wins; otherwise a channel
        named after a direction takes its master's line (MOSI, ``specs/bench.yaml``); a single
        unnamed channel goes to ``direction``."""
        if self.channel_map:
            return [Route(direction, line) for direction, (name, line) in self.channel_map.items()
                    if name.lower() == channel.lower() or (name == "" and n_channels_hint == 1)]
        low = channel.lower()
        chans = bench_spec()["channels"]
        for direction in DIRECTIONS:
            if direction in low:
                return [Route(direction, str(chans[direction]["line"]))]
        if n_channels_hint == 1:
            line = str(chans[self.direction or "h2e"]["line"])
            return [Route(self.direction, line)]
        raise InputError(
            f"channel {channel!r}: its name says neither h2e nor e2h; give --channel-map "
            f"h2e=NAME[:LINE],e2h=NAME[:LINE]")


def parse_channel_map(text: str) -> dict[str, tuple[str, str]]:
    """``h2e=SPI 1:mosi,e2h=SPI 2`` -> {"h2e": ("SPI 1", "mosi"), "e2h": ("SPI 2", "mosi")}.
    An empty NAME means the capture's only channel (``h2e=:mosi,e2h=:miso`` for one
    full-duplex bus)."""
    out: dict[str, tuple[str, str]] = {}
    for part in text.split(","):
        direction, eq, rest = part.partition("=")
        direction = direction.strip()
        if not eq or direction not in DIRECTIONS:
            raise UsageError(f"--channel-map: {part!r} is not h2e=NAME[:LINE] or e2h=NAME[:LINE]")
        name, _, line = rest.rpartition(":") if ":" in rest else (rest, "", "")
        line = line.strip().lower() or str(bench_spec()["channels"][direction]["line"])
        if line not in LINES:
            raise UsageError(f"--channel-map: line {line!r} is not mosi or miso")
        if direction in out:
            raise UsageError(f"--channel-map: {direction} given twice")
        out[direction] = (name.strip(), line)
    return out


def parse_signals(items: list[str]) -> dict[str, tuple[str, str, str, str | None]]:
    """``h2e=CS0,CLK0,MOSI0[,MISO0]`` (repeatable) -> channel -> signal names."""
    out: dict[str, tuple[str, str, str, str | None]] = {}
    for item in items:
        chan, eq, rest = item.partition("=")
        names = [n.strip() for n in rest.split(",")]
        if not eq or not chan.strip() or len(names) not in (3, 4) or not all(names):
            raise UsageError(f"--signals: {item!r} is not CHANNEL=CS,CLK,MOSI[,MISO]")
        out[chan.strip()] = (names[0], names[1], names[2], names[3] if len(names) == 4 else None)
    return out


def signal_name(channel: str, signal: str) -> str:
    return str(bench_spec()["vcd"]["name_format"]).format(channel=channel, signal=signal)
