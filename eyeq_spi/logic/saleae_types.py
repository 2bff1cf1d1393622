"""The Saleae readers' vocabulary (:mod:`eyeq_spi.logic.saleae`, also used by the VCD reader):
the byte source, a transfer being read, the reading state carried from chunk to chunk, and the
capture's time format."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Protocol

from eyeq_spi.logic.options import Route

MAX_LINE = 1 << 16


class ByteSource(Protocol):
    def read(self, size: int = -1) -> bytes: ...


class OpenTransfer:
    """A transfer between chip select falling and rising: its time and bytes per line."""

    __slots__ = ("lines", "time")

    def __init__(self, time: float | None) -> None:
        self.time = time
        self.lines: dict[str, bytearray] = {"mosi": bytearray(), "miso": bytearray()}


def seconds(text: str) -> float:
    """A capture time: seconds (Logic 1.x, Logic 2's default), or an ISO 8601 date and time
    (Logic 2's "Use ISO8601 timestamps" export option) as seconds since the epoch, UTC when
    no zone is given; ValueError for anything else."""
    try:
        return float(text)
    except ValueError:
        pass
    stamp_text = text.strip().strip('"')
    if len(stamp_text) < 10 or stamp_text[4:5] != "-":
        raise ValueError(text)
    stamp = datetime.fromisoformat(stamp_text)
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=UTC)
    return stamp.timestamp()


@dataclass
class Saleae2State:
    open_: dict[str, OpenTransfer | None]
    routes: dict[str, list[Route]]
    results: int = 0
    enables: int = 0


@dataclass
class Saleae1State:
    tr: OpenTransfer | None = None
    packet: str | None = None
