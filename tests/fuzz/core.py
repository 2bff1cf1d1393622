"""What every fuzz target shares: an input reader, the finding types, a time limit, figures."""

from __future__ import annotations

import contextlib
import random
import signal
import struct
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from types import FrameType

Target = Callable[[bytes], None]
FIGURES: Counter[str] = Counter()  # inputs, frames, messages... fed by the targets


class Finding(AssertionError):  # noqa: N818 - the name says what was found
    """A fuzz oracle was violated (not a crash: the code ran, but did something forbidden)."""


class Hang(Exception):  # noqa: N818 - the name says what was found
    """One input ran over its time limit."""


@contextlib.contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    """Raise :class:`Hang` in the main thread when the block runs over ``seconds``."""

    def on_alarm(signum: int, frame: FrameType | None) -> None:
        raise Hang(f"over {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


class Reader:
    """Consumes a fuzz input front to back; reads past the end give zeros, so every input is a
    valid program for the target."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.pos = 0

    @property
    def done(self) -> bool:
        return self.pos >= len(self.data)

    def take(self, n: int) -> bytes:
        out = self.data[self.pos:self.pos + max(0, n)]
        self.pos += max(0, n)
        return out

    def u8(self) -> int:
        b = self.take(1)
        return b[0] if b else 0

    def u16(self) -> int:
        return int.from_bytes(self.take(2).ljust(2, b"\0"), "little")

    def u32(self) -> int:
        return int.from_bytes(self.take(4).ljust(4, b"\0"), "little")

    def choice(self, options: list[object] | tuple[object, ...]) -> object:
        return options[self.u8() % len(options)]

    def number(self) -> float:
        """Any double, with the nasty ones (NaN, inf, huge, tiny, -0) well represented."""
        k = self.u8() % 10
        if k == 0:
            return float("nan")
        if k == 1:
            return float("inf") if self.u8() & 1 else float("-inf")
        if k == 2:
            return (1.0 if self.u8() & 1 else -1.0) * 10.0 ** (self.u8() % 310)
        if k == 3:
            return -0.0
        if k in (4, 5):
            return float(struct.unpack("<d", self.take(8).ljust(8, b"\0"))[0])
        return float(int.from_bytes(self.take(2).ljust(2, b"\0"), "little", signed=True)) / 8


@dataclass
class SliceResult:
    """What a coverage-free run of one target found."""

    inputs: int = 0
    findings: list[tuple[str, bytes]] = field(default_factory=list)

    def note(self, exc: BaseException, data: bytes) -> None:
        if len(self.findings) < 5:
            self.findings.append((f"{type(exc).__name__}: {exc}"[:300], data))


def mutate(rng: random.Random, data: bytes) -> bytes:
    """Damage at the byte level: flips, inserts, deletes, cuts, copies, nasty words."""
    b = bytearray(data)
    for _ in range(rng.randrange(1, 8)):
        op = rng.randrange(6)
        pos = rng.randrange(len(b) + 1)
        if op == 0 and b:
            b[min(pos, len(b) - 1)] ^= 1 << rng.randrange(8)
        elif op == 1:
            b[pos:pos] = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 16)))
        elif op == 2:
            del b[pos:pos + rng.randrange(1, 300)]
        elif op == 3:
            b = b[: rng.randrange(len(b) + 1)]
        elif op == 4 and b:
            start = rng.randrange(len(b))
            b[pos:pos] = b[start:start + rng.randrange(1, 400)]
        elif op == 5 and len(b) >= 4:
            at = rng.randrange(len(b) - 3)
            b[at:at + 4] = rng.choice([b"\xff\xff\xff\xff", b"\0\0\0\0", b"\x7f\xff\xff\xff"])
    return bytes(b)
