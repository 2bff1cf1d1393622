"""Write SPI captures as pcapng (``specs/capture.yaml``) and read them with python-pcapng.

A file that ends inside a block (a writer killed mid-block by another tool, a copy cut short) is
read up to its last whole block when the caller passes a :class:`Tail`, which then says how many
bytes at the end were ignored; without one it raises :class:`TruncatedInputError`.
"""

from __future__ import annotations

import re
import struct
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Protocol

from eyeq_spi.catalog.messages import SwKey, catalog, sw_release_text
from eyeq_spi.errors import EyeqError, InputError, OutputError, TruncatedInputError

if TYPE_CHECKING:
    import threading

DIRECTIONS = ("h2e", "e2h")
SW_COMMENT = "eyeq-spi sw={release}"  # specs/capture.yaml release_comment: "eyeq-spi sw=8.1"


@dataclass
class Tail:
    """What a reader left unread at the end of a capture: ``ignored`` bytes of an incomplete
    block that starts at byte ``at`` (0 bytes: the file ended on a block boundary)."""

    ignored: int = 0
    at: int = 0

    def take(self, exc: TruncatedInputError) -> None:
        self.ignored, self.at = exc.ignored, exc.at

    def note(self, name: str) -> str:
        """The one line a reader prints about it."""
        return (f"{name}: the capture ends inside a block: read up to the last whole block and "
                f"ignored the last {self.ignored} byte{'' if self.ignored == 1 else 's'} "
                f"(from byte {self.at})")


def release_from_comment(text: str) -> SwKey | None:
    """The ``specs/`` key of an ``eyeq-spi sw=<release>`` comment (None: no such comment, or a
    release ``specs/`` does not know)."""
    value = _comment_value(str(_spec().get("release_comment", SW_COMMENT)), "{release}", text)
    try:
        return None if value is None else catalog().sw(value)
    except EyeqError:
        return None


def _comment_value(template: str, field: str, text: str) -> str | None:
    """The word after ``template``'s text before ``field`` in the comment ``text``, or None."""
    match = re.search(re.escape(template.split(field)[0]) + r"(\S+)", text)
    return None if match is None else match.group(1)


def _shb_comments(head: bytes) -> list[str]:
    """The ``opt_comment`` options of the Section Header Block at the start of ``head`` (the
    first bytes of a pcapng file)."""
    if len(head) < 28 or head[:4] != PCAPNG_MAGIC:
        return []
    endian = {b"\x4d\x3c\x2b\x1a": "<", b"\x1a\x2b\x3c\x4d": ">"}.get(head[8:12])
    if endian is None:
        return []
    end = min(struct.unpack_from(f"{endian}I", head, 4)[0] - 4, len(head))
    # after type, length, byte-order magic, version, section length
    return [value.decode("utf-8", "replace")
            for code, value in pcapng_options(head, 24, end, endian) if code == 1]


def pcapng_options(block: bytes | bytearray, pos: int, end: int, endian: str = "<"
                   ) -> Iterator[tuple[int, bytes]]:
    """The (code, value) options of a pcapng block from byte ``pos`` up to ``end`` or
    opt_endofopt."""
    while pos + 4 <= end:
        code, size = struct.unpack_from(f"{endian}HH", block, pos)
        if code == 0:
            return
        yield code, bytes(block[pos + 4 : pos + 4 + size])
        pos += 4 + size + (-size % 4)


def recorded_release(head: bytes) -> SwKey | None:
    """The release recorded in the Section Header Block at the start of ``head`` (the first
    bytes of a pcapng file), or None."""
    for text in _shb_comments(head):
        key = release_from_comment(text)
        if key is not None:
            return key
    return None


def recorded_clock(head: bytes) -> str | None:
    """The clock a capture's timestamps were read from, as its Section Header Block records it
    (``specs/capture.yaml`` ``clock_comment``): ``"virtual"`` or ``"monotonic"``; None when it
    does not say (a capture written before the comment existed, or by another tool)."""
    for text in _shb_comments(head):
        value = _comment_value(str(_spec()["clock_comment"]), "{clock}", text)
        if value in _spec()["clocks"]:
            return value
    return None


def _spec() -> dict[str, Any]:
    return dict(catalog().raw["capture.yaml"]["capture"])


def release_sniff_transfers() -> int:
    """How many first transfers of a capture without its release comment are looked at for
    the release (``specs/capture.yaml`` ``release_sniff_transfers``): dissect and the Lua
    dissector alike."""
    return int(_spec()["release_sniff_transfers"])


@dataclass(frozen=True, slots=True)
class Transfer:
    """One transfer as read from a capture: time, direction, bytes."""

    time: float | None
    direction: str | None  # "h2e" | "e2h" | None when unknown
    data: bytes


PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"


class Readable(Protocol):
    def read(self, size: int = -1, /) -> bytes: ...


class PeekStream:
    """A binary stream with its first bytes already read (stdin cannot seek):
    ``peek_size`` bytes read here, or the ``head`` a caller already read."""

    def __init__(self, fh: Readable, peek_size: int = 4096, head: bytes | None = None) -> None:
        self.fh = fh
        self.head = fh.read(peek_size) if head is None else head
        self.pos = 0

    def tell(self) -> int:
        return self.pos

    def read(self, size: int = -1) -> bytes:
        out = self._read(size)
        self.pos += len(out)
        return out

    def _read(self, size: int) -> bytes:
        if self.head:
            if size < 0:
                out, self.head = self.head + self.fh.read(), b""
                return out
            out, self.head = self.head[:size], self.head[size:]
            if len(out) < size:
                out += self.fh.read(size - len(out))
            return out
        return self.fh.read(size)


MAX_BLOCK = 1 << 20  # a pcapng block over 1 MiB is corrupt for us (a transfer is 128 bytes)


class CaptureWriter:
    """Streams transfers to a pcapng file: ``write(direction, time, transfer)``.

    Crash-safe: whole blocks only go to the file, in one unbuffered write whenever the buffer
    holds ``FLUSH_BYTES`` or ``flush_interval_s`` (``specs/capture.yaml``) has passed by
    ``clock`` (with ``idle_flush``, also from a daemon thread when no transfer comes), so a
    process that dies loses at most that much traffic. The release (``sw``; default the newest)
    is recorded as ``eyeq-spi sw=<release>`` on the Section Header Block and first packet."""

    FLUSH_BYTES = 1 << 16
    FLUSH_S = 1.0

    def __init__(self, path: str | Path, sw: str | None = None, *,
                 clock: Callable[[], float] = time.monotonic, idle_flush: bool = True,
                 flush_s: float | None = None, time_base: str | None = None) -> None:
        spec = _spec()
        cat = catalog()
        try:
            self.release = sw_release_text(cat.sw(sw))
        except EyeqError as exc:
            raise OutputError(str(exc)) from None
        self.comment = str(spec.get("release_comment", SW_COMMENT)).format(release=self.release)
        self.flush_s = float(flush_s or spec.get("flush_interval_s", self.FLUSH_S))
        try:
            self._fh: IO[bytes] = open(path, "wb", buffering=0)  # noqa: SIM115 - see close()
        except OSError as exc:
            raise OutputError(f"cannot write capture {path}: {exc}") from exc
        self._clock = clock
        self._ids = {i["name"]: i["id"] for i in spec["interfaces"]}
        self._scale = 10 ** spec["timestamp_resolution"]
        if time_base is not None and time_base not in spec["clocks"]:
            raise OutputError(f"unknown capture clock {time_base!r} "
                               f"(known: {', '.join(spec['clocks'])})")
        self.time_base = time_base
        comments = [self.comment]
        if time_base is not None:  # what the timestamps were read from
            comments.append(str(spec["clock_comment"]).format(clock=time_base))
        self._buf = bytearray(_shb(spec["application"], comments))
        for iface in sorted(spec["interfaces"], key=lambda i: int(i["id"])):
            self._buf += _idb(spec["link_type"], iface["name"], iface["description"],
                              spec["timestamp_resolution"])
        self._last_flush = clock()
        import threading  # here: reading a capture never needs it

        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.flush()
        self.count = 0
        self._idle: threading.Thread | None = None
        if idle_flush:
            self._idle = threading.Thread(target=self._idle_flush, name="capture-flush",
                                          daemon=True)
            self._idle.start()

    def _idle_flush(self) -> None:
        """What waits in the buffer goes to the file when no transfer came to write it."""
        while not self._stop.wait(self.flush_s / 2):
            with self._lock:
                if self._buf and not self._fh.closed and \
                        self._clock() - self._last_flush >= self.flush_s:
                    try:
                        self._flush()
                    except OutputError:
                        return  # the next write or close() reports it

    def write(self, direction: str, time: float, transfer: bytes) -> None:
        with self._lock:
            self._write(direction, time, transfer)

    def _write(self, direction: str, time: float, transfer: bytes) -> None:
        opts = _options([(1, self.comment.encode())]) if self.count == 0 else b""
        self._encode_one(self._ids[direction], time, bytes(transfer), opts)
        self.count += 1
        if len(self._buf) >= self.FLUSH_BYTES or self._clock() - self._last_flush >= self.flush_s:
            self._flush()

    def _encode_one(self, iface: int, time: float, data: bytes, opts: bytes) -> None:
        """One Enhanced Packet Block into the buffer; a time without a
        pcapng timestamp (not a number, infinite, past 2**64 ticks) is an :class:`OutputError`
        and writes nothing."""
        pad = -len(data) % 4
        size = 32 + len(data) + pad + len(opts)
        try:
            ticks = max(0, round(time * self._scale))
            head = _EPB_HEAD.pack(6, size, iface, ticks >> 32, ticks & 0xFFFFFFFF, len(data),
                                  len(data))
        except (ValueError, OverflowError, TypeError, struct.error):
            raise OutputError(f"cannot write capture {self._fh.name}: transfer time {time!r} "
                              "has no pcapng timestamp") from None
        self._buf += head
        self._buf += data
        self._buf += b"\0" * pad
        self._buf += opts
        self._buf += size.to_bytes(4, "little")

    def flush(self) -> None:
        """Write every whole block buffered so far."""
        with self._lock:
            self._flush()

    def _flush(self) -> None:
        view = memoryview(self._buf)
        try:
            while view:
                written = self._fh.write(view)
                view = view[written or 0:]
        except OSError as exc:
            raise OutputError(f"cannot write capture {self._fh.name}: {exc}") from None
        finally:
            view.release()
        self._buf.clear()
        self._last_flush = self._clock()

    def close(self) -> None:
        import threading

        self._stop.set()
        if self._idle is not None and self._idle is not threading.current_thread():
            self._idle.join()
        if not self._fh.closed:
            try:
                self.flush()
            finally:
                self._fh.close()

    def __enter__(self) -> CaptureWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_EPB_HEAD = struct.Struct("<IIIIIII")  # type, length, interface, ts high, ts low, caplen, len


def _options(opts: list[tuple[int, bytes]]) -> bytes:
    """pcapng options, then opt_endofopt."""
    out = bytearray()
    for code, value in opts:
        out += struct.pack("<HH", code, len(value)) + value + b"\0" * (-len(value) % 4)
    return bytes(out + b"\0\0\0\0")


def _block(btype: int, body: bytes) -> bytes:
    size = 12 + len(body)
    return struct.pack("<II", btype, size) + body + struct.pack("<I", size)


def _shb(application: str, comments: list[str]) -> bytes:
    # byte-order magic, version 1.0, section length unknown (-1); opt_comments, shb_userappl
    return _block(int.from_bytes(PCAPNG_MAGIC, "little"),
                  struct.pack("<IHHq", 0x1A2B3C4D, 1, 0, -1)
                  + _options([(1, c.encode()) for c in comments]
                             + [(4, application.encode())]))


def _idb(link_type: int, name: str, description: str, tsresol: int) -> bytes:
    return _block(1, struct.pack("<HHI", link_type, 0, 0)
                  + _options([(2, name.encode()), (3, description.encode()),
                              (9, bytes([tsresol]))]))


def read_pcapng(fh: IO[bytes], tail: Tail | None = None) -> Iterator[Transfer]:
    """Stream the transfers of a pcapng capture. Malformed files raise :class:`InputError`
    (see :class:`PcapngGuard`); a truncated one too, unless ``tail`` is given: then it ends
    after the last whole block and ``tail`` says what was left."""
    from pcapng import FileScanner, blocks
    from pcapng.exceptions import PcapngException

    guard = PcapngGuard(fh)
    try:
        yield from _scan(guard, FileScanner, blocks, PcapngException)
    except TruncatedInputError as exc:
        if tail is None:
            raise
        tail.take(exc)


def _scan(guard: PcapngGuard, scanner: Any, blocks: Any, pcapng_error: type[Exception]
          ) -> Iterator[Transfer]:
    names: dict[int, str | None] = {}
    scales: dict[int, float] = {}
    try:
        for block in scanner(guard):
            if isinstance(block, blocks.InterfaceDescription):
                iid = len(names)
                name = block.options.get("if_name") if block.options else None
                names[iid] = name if name in DIRECTIONS else None
                try:
                    scales[iid] = float(block.timestamp_resolution)  # seconds per tick
                except (AttributeError, TypeError, ValueError):
                    scales[iid] = 1e-6
            elif isinstance(block, blocks.EnhancedPacket):
                iid = block.interface_id
                ticks = (block.timestamp_high << 32) | block.timestamp_low
                yield Transfer(ticks * scales.get(iid, 1e-6), names.get(iid),
                             bytes(block.packet_data))
    except InputError:
        raise
    except (pcapng_error, struct.error, EOFError, ValueError, KeyError) as exc:
        raise (guard.error or InputError(f"malformed pcapng: {exc}")) from None
    except Exception as exc:
        raise (guard.error or InputError(
            f"malformed pcapng ({type(exc).__name__}: {exc})")) from None
    if guard.error is not None:
        raise guard.error
    guard.at_end()


class PcapngGuard:
    """Watches the bytes a pcapng reader consumes and walks the block framing itself, so that
    whatever reader runs: a file that ends inside a block is reported as truncated (python-pcapng
    stops silently when a read at a field boundary finds the end of the file), and no single read
    or block may exceed :data:`MAX_BLOCK` (memory stays bounded for a corrupt length)."""

    def __init__(self, stream: IO[bytes]) -> None:
        self.stream = stream
        self.pos = 0
        self.block_start = 0
        self.hdr = b""
        self.left = 0  # bytes of the current block still to come once its header is known
        self.endian: str | None = None
        self.error: InputError | None = None

    def tell(self) -> int:
        return self.pos  # python-pcapng checks block alignment with it

    def read(self, size: int = -1) -> bytes:
        if size < 0 or size > MAX_BLOCK:
            self._fail(f"malformed pcapng: a block of {size} bytes at byte {self.block_start} is "
                       f"over the {MAX_BLOCK >> 20} MiB limit")
        data = self.stream.read(size)
        self._feed(data)
        if len(data) < size:
            self.at_end()
        return data

    def at_end(self) -> None:
        if self.hdr or self.left:
            left = self.pos - self.block_start
            self.error = self.error or TruncatedInputError(
                f"truncated pcapng: the file ends {left} bytes into the block that starts at "
                f"byte {self.block_start}", ignored=left, at=self.block_start)
            raise self.error

    def _fail(self, message: str) -> None:
        self.error = self.error or InputError(message)
        raise self.error

    def _feed(self, data: bytes) -> None:
        pos, length = 0, len(data)
        while pos < length:
            if self.left == 0:
                take = min(12 - len(self.hdr), length - pos)
                self.hdr += data[pos:pos + take]
                pos += take
                if len(self.hdr) == 12:
                    self._header()
            else:
                step = min(self.left, length - pos)
                self.left -= step
                pos += step
            if self.left == 0 and not self.hdr:
                self.block_start = self.pos + pos
        self.pos += length

    def _header(self) -> None:
        hdr, self.hdr = self.hdr, b""
        if hdr[:4] == PCAPNG_MAGIC:
            bom = hdr[8:12]
            self.endian = {b"\x4d\x3c\x2b\x1a": "<", b"\x1a\x2b\x3c\x4d": ">"}.get(bom)
            if self.endian is None:
                self._fail("malformed pcapng: bad byte-order magic in the section header")
        elif self.endian is None:
            self._fail("malformed pcapng: it does not start with a section header")
        length = struct.unpack(f"{self.endian}I", hdr[4:8])[0]
        if length % 4 or not 12 <= length <= MAX_BLOCK:
            self._fail(f"malformed pcapng: block at byte {self.block_start} has length {length}"
                       f" (a multiple of 4 in 12..{MAX_BLOCK} expected)")
        self.left = length - 12
        if self.left == 0:
            self.block_start += length

