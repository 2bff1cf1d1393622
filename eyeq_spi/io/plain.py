"""Capture inputs, streamed with bounded memory, and the plain formats: ``pcapng``
(``specs/capture.yaml``), ``hex`` (one transfer per line: ``[TIME] [h2e|e2h] HEX``, ``#``
comments) and ``raw`` (128-byte transfers of one channel).

:func:`open_transfers` opens any capture reader of the registry (:mod:`eyeq_spi.io`), detected
by its first bytes unless named. Unknown or empty input raises :class:`InputError`, a cut
transfer :class:`TruncatedInputError` (a pcapng file cut inside a block is read up to its last
whole block when the caller passes a :class:`Tail`).
"""

from __future__ import annotations

import binascii
import re
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import IO

from eyeq_spi import io as registry
from eyeq_spi.capture.pcapng_io import PCAPNG_MAGIC, PeekStream, Tail, Transfer, read_pcapng
from eyeq_spi.errors import InputError, TruncatedInputError
from eyeq_spi.link.frame import FRAME_SIZE, FrameCodec
from eyeq_spi.logic.options import SpiOptions

FORMATS = registry.names(registry.CAPTURE_READER)
LOGIC_FORMATS = tuple(f.name for f in registry.formats(registry.CAPTURE_READER)
                      if f.takes == "spi")  # logic-analyzer captures (eyeq_spi.logic)
_HEX_LINE = re.compile(
    rb"^\s*(?:[+-]?\d+(?:\.\d*)?(?:[eE][+-]?\d+)?\s+)?(?:(?:h2e|e2h)\s+)?[0-9A-Fa-f:\s]*$"
)
__all__ = ["FORMATS", "LOGIC_FORMATS", "InputError", "PeekStream", "TruncatedInputError",
           "detect", "open_transfers"]


# Bytes no text format can begin with: not ASCII whitespace for bytes.lstrip or the hex regex,
# not whitespace for str.strip (0x1C-0x1F are), not a letter, quote, digit or '$'. An EyeQ frame's
# first byte (the header word's low byte: 0x04 ACK, 0x08 DATA) is one of them.
_BINARY_LEAD = frozenset([*range(0x00, 0x09), *range(0x0E, 0x1C)])


def detect(head: bytes) -> str:
    """The name of the capture reader for a file that starts with ``head``."""
    return _detect(head, text=not head or head[0] not in _BINARY_LEAD)


def _detect(head: bytes, text: bool) -> str:
    """``text``: try the text formats (logic-analyzer exports, hex). A head that starts with a
    byte of ``_BINARY_LEAD`` can be none of them, so a raw capture skips their sniffers (and the
    import of eyeq_spi.logic): the answer is the same (tests/test_dissect_stats_fast.py)."""
    if not head:
        raise InputError("empty input")
    for _, sniff in registry.sniffers(text):
        kind = sniff(head)
        if kind is not None:
            return kind
    if len(head) < FRAME_SIZE:
        raise InputError(f"input of {len(head)} bytes is shorter than one 128-byte transfer")
    raise InputError("not an EyeQ SPI capture: no valid frame in the first transfers "
                     f"(formats: {', '.join(FORMATS)})")


def sniff_pcapng(head: bytes) -> str | None:
    return "pcapng" if head[:4] == PCAPNG_MAGIC else None


def sniff_hex(head: bytes) -> str | None:
    sample = head[:2048]
    lines = sample.split(b"\n")
    if len(lines) > 1:
        lines = lines[:-1]  # the last line of the sample may be cut
    body = [line.split(b"#", 1)[0] for line in lines]
    if all(_HEX_LINE.match(line) for line in body) and re.search(rb"[0-9A-Fa-f]{16}", sample):
        return "hex"
    return None


def sniff_raw(head: bytes) -> str | None:
    """``raw`` when one of the first transfers is a link frame with a good CRC. The last
    sniffer: a classic pcap file (which no reader takes) is refused here."""
    if head[:4] in (b"\xd4\xc3\xb2\xa1", b"\xa1\xb2\xc3\xd4"):
        raise InputError("classic pcap is not supported: convert with editcap -F pcapng")
    codec = FrameCodec()
    for index in range(min(len(head) // FRAME_SIZE, 8)):
        transfer = head[index * FRAME_SIZE:(index + 1) * FRAME_SIZE]
        if codec.crc_ok(transfer, codec.decode(transfer)):
            return "raw"
    return None


def open_transfers(stream: IO[bytes], fmt: str | None = None,
                 direction: str | None = None, spi: SpiOptions | None = None,
                 tail: Tail | None = None) -> tuple[str, Iterator[Transfer]]:
    """The format and the transfers of a capture, by any capture reader of the registry.
    ``fmt``: the reader's name (else :func:`detect`); ``direction``: the channel of an input
    that holds one; ``spi``: how a logic-analyzer export maps onto the channels; ``tail``: a
    pcapng file that ends inside a block is read up to its last whole block and ``tail`` says
    what was left (else it is a :class:`TruncatedInputError`)."""
    peek = PeekStream(stream)
    kind = fmt or detect(peek.head)
    entry = registry.get(kind, registry.CAPTURE_READER)
    read = registry.load(entry)
    if entry.takes == "spi":
        return kind, _logic(read, peek, spi or SpiOptions(direction=direction), kind)
    return kind, read(peek, tail if entry.takes == "tail" else direction)


def _logic(read: Callable[[PeekStream, SpiOptions], Iterator[Transfer]], peek: PeekStream,
           spi: SpiOptions, kind: str) -> Iterator[Transfer]:
    """A logic-analyzer reader's transfers; its errors as :class:`InputError`."""
    if not peek.head:
        raise InputError("empty input")
    try:
        yield from read(peek, spi)
    except InputError as exc:
        raise InputError(f"{kind}: {exc}") from None


MAX_HEX_LINE = 1 << 14  # characters; a 128-byte transfer with time and separators needs ~420


def read_pcapng_input(peek: PeekStream, tail: Tail | None = None) -> Iterator[Transfer]:
    """The transfers of a pcapng capture; its errors as :class:`InputError`."""
    if peek.head[:4] != PCAPNG_MAGIC:
        raise InputError("not a pcapng file")
    return _pcapng(peek, tail)


def _pcapng(peek: PeekStream, tail: Tail | None = None) -> Iterator[Transfer]:
    count = 0
    for transfer in read_pcapng(peek, tail):  # type: ignore[arg-type]
        count += 1
        yield transfer
    if count == 0:
        raise InputError("pcapng capture without any transfer (no Enhanced Packet Block)")


def read_raw(peek: PeekStream, direction: str | None = None) -> Iterator[Transfer]:
    """128-byte transfers of one channel (``direction``), without times. A file none of whose
    first transfers is a link frame with a good CRC never was a raw capture."""
    if not peek.head:
        raise InputError("empty input")
    if sniff_raw(peek.head) is None:
        raise InputError("not a raw capture: no link frame with a good CRC in its first "
                         f"{min(len(peek.head) // FRAME_SIZE, 8)} transfers of 128 bytes")
    return _raw(peek, direction)


def _raw(peek: PeekStream, direction: str | None) -> Iterator[Transfer]:
    while True:
        chunk = peek.read(FRAME_SIZE * 512)
        if not chunk:
            return
        full = len(chunk) - len(chunk) % FRAME_SIZE
        for start in range(0, full, FRAME_SIZE):
            yield Transfer(None, direction, chunk[start:start + FRAME_SIZE])
        if full != len(chunk):
            rest = chunk[full:] + peek.read(FRAME_SIZE - (len(chunk) - full))
            if len(rest) == FRAME_SIZE:
                yield Transfer(None, direction, rest)
                continue
            raise TruncatedInputError(f"truncated raw capture: {len(rest)} bytes left over "
                                      "after the last whole 128-byte transfer")


def read_hex(peek: PeekStream, direction: str | None = None) -> Iterator[Transfer]:
    """One transfer per line; ``direction`` for lines that do not name theirs. A file whose
    first lines are not such lines never was a hex capture."""
    if peek.head and sniff_hex(peek.head) is None:
        raise InputError("not a hex capture: its first lines are not transfers in hex "
                         "([TIME] [h2e|e2h] HEX BYTES)")
    return _hex(peek, direction)


def _hex(peek: PeekStream, direction: str | None) -> Iterator[Transfer]:
    buf = b""
    lineno = 0
    seen = False
    while True:
        chunk = peek.read(1 << 16)
        buf += chunk
        lines = buf.split(b"\n")
        buf = lines.pop() if chunk else b""
        if not chunk and lines and not lines[-1]:
            lines.pop()  # the end of the last line, not a line of its own
        for raw_line in lines:
            lineno += 1
            if len(raw_line) > MAX_HEX_LINE:
                raise InputError(f"line {lineno}: longer than {MAX_HEX_LINE} characters; one "
                                 "line holds one transfer")
            transfer = _hex_line(raw_line, lineno, direction)
            if transfer is not None:
                seen = True
                yield transfer
        if len(buf) > MAX_HEX_LINE:  # bounded memory: never hold a pathological line
            raise InputError(f"line {lineno + 1}: longer than {MAX_HEX_LINE} characters; one "
                             "line holds one transfer")
        if not chunk:
            if not seen:
                raise InputError(f"no transfer in {lineno} line(s) of hex text")
            return


def _hex_line(raw_line: bytes, lineno: int, direction: str | None) -> Transfer | None:
    line = raw_line.split(b"#", 1)[0].strip()
    if not line:
        return None
    tokens = line.decode("ascii", "replace").split()
    time_s: float | None = None
    dirn = direction
    if len(tokens) > 1 and re.fullmatch(r"[+-]?\d+(\.\d*)?([eE][+-]?\d+)?", tokens[0]) and \
            not re.fullmatch(r"[0-9A-Fa-f]{16,}", tokens[0]):
        time_s = float(tokens.pop(0))
    if tokens and tokens[0] in ("h2e", "e2h"):
        dirn = tokens.pop(0)
    text = "".join(tokens).replace(":", "")
    try:
        data = binascii.unhexlify(text)
    except (binascii.Error, ValueError):
        shown = "".join(c if c.isprintable() else "?" for c in text[:40])
        raise InputError(f"line {lineno}: not hex bytes: {shown!r}") from None
    if not data:
        raise InputError(f"line {lineno}: no bytes")
    return Transfer(time_s, dirn, data)


def write_raw(transfers: Iterable[Transfer], path: str | Path, *, direction: str = "e2h") -> int:
    """The transfers of ``direction`` (the raw format holds one channel and no times)."""
    count = 0
    with open(path, "wb") as fh:
        for transfer in transfers:
            if transfer.direction in (direction, None):
                fh.write(transfer.data)
                count += 1
    return count


def write_hex(transfers: Iterable[Transfer], path: str | Path) -> int:
    """One line per transfer: its time (as Python prints the float: it reads back the same),
    direction and bytes in hex; a field the transfer lacks is left out."""
    count = 0
    with open(path, "w", encoding="ascii", newline="\n") as fh:
        for transfer in transfers:
            head = ([] if transfer.time is None else [repr(transfer.time)]) + \
                ([] if transfer.direction is None else [transfer.direction])
            fh.write(" ".join([*head, binascii.hexlify(transfer.data).decode()]) + "\n")
            count += 1
    return count
