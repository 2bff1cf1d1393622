"""A seeded lossy SPI channel for the memory pair's fault hook (``MemoryAdapter.mangle``).

Per transfer one exclusive fault class is drawn, so that each injected fault maps to exactly one
receiver reaction: ``drop`` (nothing arrives), ``duplicate`` (twice, back to back), ``reorder``
(held and delivered right after the next transfer), ``truncate`` (the first 1..127 bytes: chip
select rose early, L8), otherwise independent bit flips at ``profile.ber`` per bit (geometric
gaps: exactly Bernoulli per bit over the run). Each injection is recorded as an
:class:`Injected`, which a soak compares with the receiver's counters (L3/L5/L6/L8)."""

from __future__ import annotations

import math
import random
from collections import Counter
from dataclasses import dataclass, field

from eyeq_spi.errors import UsageError
from eyeq_spi.link.frame import FRAME_SIZE, FrameCodec, FrameKind

CRC_COVERED_CONTROL = 6  # L3: an ACK/NAK's CRC covers bytes 0..3; bytes 4..5 are the CRC itself
KINDS = ("flip", "drop", "duplicate", "reorder", "truncate")
FRAME_NAMES = {kind.value: kind.name for kind in FrameKind}


@dataclass(frozen=True)
class FaultProfile:
    """Per-transfer probabilities of each fault class, and the bit error rate."""

    ber: float = 1e-5
    drop: float = 0.01
    duplicate: float = 0.01
    reorder: float = 0.01
    truncate: float = 0.01

    def __post_init__(self) -> None:
        for name in ("ber", "drop", "duplicate", "reorder", "truncate"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise UsageError(f"{name} must be in [0, 1)")
        if self.drop + self.duplicate + self.reorder + self.truncate >= 1.0:
            raise UsageError("the exclusive fault classes must sum to less than 1")

    @classmethod
    def with_loss(cls, loss: float) -> FaultProfile:
        """The default profile with ``drop`` raised so that about ``loss`` of the frames never
        arrive intact: BER 1e-5 (≈1% of 128-byte frames) + 1% truncation + the rest dropped."""
        ber_frames = 1.0 - (1.0 - 1e-5) ** (FRAME_SIZE * 8)
        drop = loss - 0.01 - ber_frames
        if drop < 0:
            raise UsageError(f"loss {loss} is below the profile's own {0.01 + ber_frames:.3f}")
        return cls(drop=drop)

    @property
    def expected_frame_loss(self) -> float:
        ber_frames = (1.0 - (1.0 - self.ber) ** (FRAME_SIZE * 8))
        clean = 1.0 - self.drop - self.duplicate - self.reorder - self.truncate
        return self.drop + self.truncate + clean * ber_frames


@dataclass(frozen=True)
class Injected:
    """One injected fault. ``frame`` is D of the original transfer (``DATA``/``ACK``/``NAK``/
    ``?``); ``crc_covered``: a flip that the L3 CRC must catch; ``after`` (reorder): D of the
    transfer that overtook it."""

    index: int
    kind: str
    frame: str
    num: int
    rsp: int
    bits: tuple[int, ...] = ()
    length: int = FRAME_SIZE
    crc_covered: bool = False
    after: str | None = None


@dataclass
class ChannelStats:
    transfers: int = 0  # transfers offered by the sender
    delivered: int = 0  # transfers handed to the receiver
    bits: int = 0
    injected: Counter[str] = field(default_factory=Counter)


class FaultyChannel:
    """A ``Mangle`` for one direction of a memory pair. ``enabled = False`` passes transfers
    through (and releases a held one)."""

    def __init__(self, profile: FaultProfile, seed: int, *, codec: FrameCodec | None = None
                 ) -> None:
        self.profile = profile
        self.rng = random.Random(seed)
        self.codec = codec or FrameCodec()
        self.enabled = True
        self.stats = ChannelStats()
        self.injected: list[Injected] = []
        self._held: tuple[int, bytes] | None = None
        self._to_flip = self._gap()

    # -- the hook ---------------------------------------------------------------------------
    def __call__(self, transfer: bytes) -> list[bytes]:
        index = self.stats.transfers
        self.stats.transfers += 1
        out = self._mangle(index, transfer)
        self.stats.delivered += len(out)
        return out

    def _mangle(self, index: int, transfer: bytes) -> list[bytes]:
        if self._held is not None:
            held_index, held = self._held
            self._held = None
            self._note(held_index, "reorder", held, after=self._kind(transfer))
            return [transfer, held]
        if not self.enabled:
            return [transfer]
        profile = self.profile
        draw = self.rng.random()
        if draw < profile.drop:
            self._note(index, "drop", transfer)
            return []
        draw -= profile.drop
        if draw < profile.duplicate:
            self._note(index, "duplicate", transfer)
            return [transfer, transfer]
        draw -= profile.duplicate
        if draw < profile.reorder:
            self._held = (index, transfer)
            return []
        draw -= profile.reorder
        if draw < profile.truncate:
            length = self.rng.randrange(1, len(transfer))
            self._note(index, "truncate", transfer, length=length)
            return [transfer[:length]]
        return [self._flip(index, transfer)]

    # -- bit errors -------------------------------------------------------------------------
    def _gap(self) -> int:
        """Bits until the next flip: geometric with parameter ``ber`` (inf when 0)."""
        if self.profile.ber <= 0:
            return 1 << 62
        draw = 1.0 - self.rng.random()  # (0, 1]
        return int(math.log(draw) / math.log1p(-self.profile.ber))

    def _flip(self, index: int, transfer: bytes) -> bytes:
        nbits = len(transfer) * 8
        self.stats.bits += nbits
        if self._to_flip >= nbits:
            self._to_flip -= nbits
            return transfer
        flipped: list[int] = []
        pos = self._to_flip
        while pos < nbits:
            flipped.append(pos)
            pos += 1 + self._gap()
        self._to_flip = pos - nbits
        buf = bytearray(transfer)
        for bit in flipped:
            buf[bit // 8] ^= 1 << (bit % 8)
        kind = self._kind(transfer)
        covered = kind not in ("ACK", "NAK") or min(flipped) < CRC_COVERED_CONTROL * 8
        self._note(index, "flip", transfer, bits=tuple(flipped), crc_covered=covered)
        return bytes(buf)

    # -- bookkeeping ------------------------------------------------------------------------
    def _kind(self, transfer: bytes) -> str:
        return self._header(transfer)[0] if len(transfer) == FRAME_SIZE else "?"

    def _header(self, transfer: bytes) -> tuple[str, int, int]:
        """D (as the frame kind's name, ``?`` if none), RSP and NUM of a transfer."""
        d, _, rsp, num = self.codec.unpack_header(int.from_bytes(transfer[:4], "little"))
        return FRAME_NAMES.get(d, "?"), rsp, num

    def _note(self, index: int, kind: str, transfer: bytes, *, bits: tuple[int, ...] = (),
              length: int = FRAME_SIZE, crc_covered: bool = False, after: str | None = None
              ) -> None:
        frame, rsp, num = self._header(transfer)
        self.injected.append(Injected(index, kind, frame, num, rsp, bits, length, crc_covered,
                                      after))
        self.stats.injected[kind] += 1

    def header_flips(self) -> int:
        """Flipped transfers with a flip in the header word (bytes 0..3, L1)."""
        return sum(1 for r in self.injected if r.kind == "flip" and min(r.bits) < 32)

    def count(self, kind: str, frame: str | None = None, *, after: str | None = None,
              crc_covered: bool | None = None) -> int:
        """How many injections of ``kind`` match the filters."""
        return sum(1 for r in self.injected if r.kind == kind
                   and (frame is None or r.frame == frame)
                   and (after is None or r.after == after)
                   and (crc_covered is None or r.crc_covered == crc_covered))
