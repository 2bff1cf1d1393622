"""pcapng captures read into arrays, many transfers at a time (the fast path's input).

A :class:`Chunk` holds up to ``chunk`` transfers: an ``(n, 128)`` byte array, their lengths, times
(NaN when a transfer has none) and direction codes; a transfer that is not 128 bytes (L8) keeps
its bytes in ``Chunk.odd`` and a zero row in ``data``. A run of Enhanced Packet Blocks of 160
bytes (what our writer produces) is checked and sliced as one array view; any other block is
walked one at a time; a big-endian section is read by python-pcapng (:func:`read_pcapng`, the
reference). Errors and a :class:`Tail` behave as :func:`read_pcapng`'s, after every complete
transfer before the fault.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from eyeq_spi.capture.pcapng_io import (
    DIRECTIONS,
    MAX_BLOCK,
    PCAPNG_MAGIC,
    PeekStream,
    Readable,
    Tail,
    Transfer,
    pcapng_options,
    read_pcapng,
)
from eyeq_spi.errors import InputError, TruncatedInputError
from eyeq_spi.link.frame import FRAME_SIZE

DIR_CODE: dict[str | None, int] = {"h2e": 0, "e2h": 1, None: -1}
DIR_NAME: dict[int, str | None] = {v: k for k, v in DIR_CODE.items()}
CHUNK = 1 << 15
READ_SIZE = 8 << 20  # bytes read at a time
_EPB, _IDB = 6, 1
_SHB = int.from_bytes(PCAPNG_MAGIC, "little")
_BOM = 0x1A2B3C4D


@dataclass
class Chunk:
    """Up to ``chunk`` transfers as arrays (module docstring)."""

    data: np.ndarray  # (n, 128) uint8
    length: np.ndarray  # (n,) int64
    time: np.ndarray  # (n,) float64, NaN for "no time"
    direction: np.ndarray  # (n,) int8, DIR_CODE
    odd: dict[int, bytes] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.length.shape[0])

    def transfer(self, index: int) -> Transfer:
        """Row ``i`` as the reference dissector's input."""
        time_s = float(self.time[index])
        data = self.odd.get(index)
        if data is None:
            data = self.data[index].tobytes()
        return Transfer(None if time_s != time_s else time_s,
                        DIR_NAME[int(self.direction[index])], data)

    def transfers(self) -> list[Transfer]:
        return [self.transfer(index) for index in range(len(self))]


def chunks_from_transfers(transfers: Iterable[Transfer], chunk: int = CHUNK) -> Iterator[Chunk]:
    """Any :class:`Transfer` stream (hex text, python-pcapng) as chunks."""
    batch: list[Transfer] = []
    for transfer in transfers:
        batch.append(transfer)
        if len(batch) >= chunk:
            yield _chunk(batch)
            batch = []
    if batch:
        yield _chunk(batch)


def _chunk(transfers: list[Transfer]) -> Chunk:
    zero = bytes(FRAME_SIZE)
    data = b"".join(t.data if len(t.data) == FRAME_SIZE else zero for t in transfers)
    return Chunk(np.frombuffer(data, np.uint8).reshape(-1, FRAME_SIZE),
                 np.asarray([len(t.data) for t in transfers], np.int64),
                 np.asarray([np.nan if t.time is None else t.time for t in transfers],
                            np.float64),
                 np.asarray([DIR_CODE[t.direction] for t in transfers], np.int8),
                 {i: t.data for i, t in enumerate(transfers) if len(t.data) != FRAME_SIZE})


def _interface(body: bytes | bytearray) -> tuple[str | None, float]:
    """An Interface Description Block's direction (its name) and tick length, as read_pcapng
    reads them."""
    name: str | None = None
    scale = 1e-6
    for code, value in pcapng_options(body, 8, len(body)):  # after link type, snaplen
        if code == 2:
            name = value.decode("utf-8", "replace")
        elif code == 9 and len(value) == 1:
            base = 2 if value[0] & 0x80 else 10
            scale = float(base ** -(value[0] & 0x7F))
    return (name if name in DIRECTIONS else None), scale


def pcapng_chunks(stream: Readable, chunk: int = CHUNK, tail: Tail | None = None
                  ) -> Iterator[Chunk]:
    """Stream a pcapng capture as chunks; see the module docstring."""
    head = stream.read(12)
    if head[:4] != PCAPNG_MAGIC:
        raise InputError("not a pcapng file")
    if len(head) < 12 or struct.unpack_from("<I", head, 8)[0] != _BOM:
        # big-endian (or too short to tell): the reference reader handles it
        yield from chunks_from_transfers(read_pcapng(PeekStream(stream, head=head), tail),  # type: ignore[arg-type]
                                       chunk)
        return
    yield from _Walker(stream, head, chunk, tail).run()


class _Walker:
    def __init__(self, stream: Readable, head: bytes, chunk: int, tail: Tail | None = None
                 ) -> None:
        self.stream = stream
        self.tail = tail
        self.buf: bytes | bytearray = head
        self.pos = 0
        self.chunk = chunk
        self.names: list[str | None] = []  # interfaces, numbered over the whole file
        self.scales: list[float] = []
        self.eof = False
        self.offset = 0  # file position of buf[0]
        self.packets = 0
        self._reset()

    def _reset(self) -> None:
        self.rows: list[np.ndarray] = []
        self.runs: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # lengths, times, dirs
        self.odd: dict[int, bytes] = {}
        self.count = 0

    def _fill(self, need: int) -> bool:
        """At least ``need`` bytes after ``pos`` in ``buf``; False at end of file. What is left
        of the buffer and the new bytes become one new buffer (the chunks handed out may still
        view the old one)."""
        while len(self.buf) - self.pos < need and not self.eof:
            more = self.stream.read(max(READ_SIZE, need))
            if not more:
                self.eof = True
                break
            self.offset += self.pos
            self.buf, self.pos = b"".join((memoryview(self.buf)[self.pos :], more)), 0
        return len(self.buf) - self.pos >= need

    def _flush(self) -> Chunk:
        length, time, direction = (np.concatenate([run[i] for run in self.runs])
                                   for i in range(3))
        chunk = Chunk(np.concatenate(self.rows), length, time, direction, self.odd)
        self._reset()
        return chunk

    def run(self) -> Iterator[Chunk]:
        try:
            yield from self._run()
        except InputError as exc:
            if self.count:  # every complete transfer before the fault
                yield self._flush()
            if not isinstance(exc, TruncatedInputError) or self.tail is None:
                raise
            if not self.packets:
                raise InputError("pcapng capture without any transfer (no whole Enhanced "
                                 "Packet Block)") from None
            self.tail.take(exc)

    def _run(self) -> Iterator[Chunk]:
        while True:
            if not self._fill(12):
                if len(self.buf) - self.pos:
                    self._truncated()
                break
            btype, blen = struct.unpack_from("<II", self.buf, self.pos)
            if blen % 4 or not 12 <= blen <= MAX_BLOCK:
                raise InputError(f"malformed pcapng: block at byte {self.offset + self.pos} has "
                                 f"length {blen} (a multiple of 4 in 12..{MAX_BLOCK} expected)")
            if btype == _EPB and self._plain_run(blen):
                if self.count >= self.chunk:
                    yield self._flush()
                continue
            if not self._fill(blen):
                self._truncated()
            body = self.buf[self.pos + 8 : self.pos + blen - 4]
            if struct.unpack_from("<I", self.buf, self.pos + blen - 4)[0] != blen:
                raise InputError("malformed pcapng: block lengths differ")
            if btype == _SHB:
                if struct.unpack_from("<I", body, 0)[0] != _BOM:
                    raise InputError("malformed pcapng: a big-endian section after a "
                                     "little-endian one")
            elif btype == _IDB:
                name, scale = _interface(body)
                self.names.append(name)
                self.scales.append(scale)
            elif btype == _EPB:
                self._one_epb(body)
            self.pos += blen
            if self.count >= self.chunk:
                yield self._flush()
        if self.count:
            yield self._flush()
        if not self.packets:
            raise InputError("pcapng capture without any transfer (no Enhanced Packet Block)")

    def _truncated(self) -> None:
        left, at = len(self.buf) - self.pos, self.offset + self.pos
        raise TruncatedInputError(f"truncated pcapng: the file ends {left} bytes into the block "
                                  f"that starts at byte {at}", ignored=left, at=at)

    def _one_epb(self, body: bytes | bytearray) -> None:
        iid, hi, lo, cap = struct.unpack_from("<IIII", body, 0)
        data = bytes(body[20 : 20 + cap])
        if len(data) != cap:
            raise InputError("malformed pcapng: packet longer than its block")
        known = iid < len(self.names)
        self.runs.append((np.array([cap], np.int64),
                          np.array([((hi << 32) | lo) * (self.scales[iid] if known else 1e-6)]),
                          np.array([DIR_CODE[self.names[iid] if known else None]], np.int8)))
        if cap == FRAME_SIZE:
            self.rows.append(np.frombuffer(data, np.uint8).reshape(1, FRAME_SIZE))
        else:
            self.odd[self.count] = data
            self.rows.append(np.zeros((1, FRAME_SIZE), np.uint8))
        self.count += 1
        self.packets += 1

    def _plain_run(self, blen: int) -> bool:
        """A run of EPBs of ``blen`` bytes carrying 128 bytes each, as one array view; False:
        the block at ``pos`` is not one of them."""
        if blen != FRAME_SIZE + 32:
            return False
        want = self.chunk - self.count
        self._fill(min(want, 4096) * blen)
        plain = min((len(self.buf) - self.pos) // blen, want)
        if plain == 0:
            return False
        blocks = np.frombuffer(self.buf, np.uint8, plain * blen, self.pos).reshape(plain, blen)
        words = blocks[:, :28].copy().view("<u4")  # type, len, iid, ts hi, ts lo, cap, orig
        good = ((words[:, 0] == _EPB) & (words[:, 1] == blen) & (words[:, 5] == FRAME_SIZE)
                & (blocks[:, -4:].copy().view("<u4")[:, 0] == blen)
                & (words[:, 2] < len(self.names)))
        plain = plain if good.all() else int(np.argmin(good))
        if plain == 0:
            return False
        head = words[:plain]
        iid = head[:, 2].astype(np.int64)
        ticks = (head[:, 3].astype(np.uint64) << np.uint64(32)) | head[:, 4].astype(np.uint64)
        scales = np.asarray(self.scales, np.float64)[iid]
        # int * float in Python rounds the int to a double first: do the same
        times = ticks.astype(np.float64) * scales
        codes = np.asarray([DIR_CODE[nm] for nm in self.names], np.int8)[iid]
        self.rows.append(blocks[:plain, 28 : 28 + FRAME_SIZE])
        self.runs.append((np.full(plain, FRAME_SIZE, np.int64), times, codes))
        self.count += plain
        self.packets += plain
        self.pos += plain * blen
        return True
