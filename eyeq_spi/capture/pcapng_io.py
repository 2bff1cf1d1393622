"""Write and read SPI captures as pcapng (``specs/capture.yaml``) with python-pcapng."""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from eyeq_spi.errors import EyeqError
from eyeq_spi.spec.catalog import catalog

DIRECTIONS = ("h2e", "e2h")


class CaptureError(EyeqError):
    """A capture file cannot be written or read."""


def _spec() -> dict[str, Any]:
    return dict(catalog().raw["capture.yaml"]["capture"])


@dataclass(frozen=True, slots=True)
class Record:
    time: float | None
    direction: str | None  # "h2e" | "e2h" | None when unknown
    data: bytes


class CaptureWriter:
    """Streams transfers to a pcapng file: ``write(direction, time, transfer)``."""

    def __init__(self, path: str | Path) -> None:
        try:
            from pcapng import FileWriter, blocks
        except ImportError as exc:  # pragma: no cover - the extra is missing
            raise CaptureError("writing captures needs python-pcapng: "
                               "pip install 'eyeq-spi[capture]'") from exc
        spec = _spec()
        self._blocks = blocks
        try:
            self._fh: IO[bytes] = open(path, "wb")  # noqa: SIM115 - closed in close()
        except OSError as exc:
            raise CaptureError(f"cannot write capture {path}: {exc}") from exc
        self._shb = blocks.SectionHeader(options={"shb_userappl": spec["application"]})
        for iface in spec["interfaces"]:
            self._shb.new_member(
                blocks.InterfaceDescription, link_type=spec["link_type"],
                options={"if_name": iface["name"], "if_description": iface["description"],
                         "if_tsresol": bytes([spec["timestamp_resolution"]])},
            )
        self._writer = FileWriter(self._fh, self._shb)
        self._ids = {i["name"]: i["id"] for i in spec["interfaces"]}
        self._scale = 10 ** spec["timestamp_resolution"]
        self.count = 0

    def write(self, direction: str, time: float, transfer: bytes) -> None:
        epb = self._shb.new_member(self._blocks.EnhancedPacket)
        epb.interface_id = self._ids[direction]
        ticks = max(0, round(time * self._scale))
        epb.timestamp_high, epb.timestamp_low = ticks >> 32, ticks & 0xFFFFFFFF
        epb.packet_data = bytes(transfer)
        self._writer.write_block(epb)
        self.count += 1

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()

    def __enter__(self) -> CaptureWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"


MAX_BLOCK = 1 << 20  # a pcapng block over 1 MiB is corrupt for us (a transfer is 128 bytes)


def read_pcapng(fh: IO[bytes]) -> Iterator[Record]:
    """Stream the transfers of a pcapng capture. Malformed or truncated files raise
    :class:`CaptureError` (see :class:`PcapngGuard`)."""
    from pcapng import FileScanner, blocks
    from pcapng.exceptions import PcapngException

    names: dict[int, str | None] = {}
    scales: dict[int, float] = {}
    guard = PcapngGuard(fh)
    try:
        for block in FileScanner(guard):
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
                yield Record(ticks * scales.get(iid, 1e-6), names.get(iid),
                             bytes(block.packet_data))
    except CaptureError:
        raise
    except (PcapngException, struct.error, EOFError, ValueError, KeyError) as exc:
        raise (guard.error or CaptureError(f"malformed pcapng: {exc}")) from None
    except Exception as exc:
        raise (guard.error or CaptureError(
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
        self.error: CaptureError | None = None

    def tell(self) -> int:
        return self.pos  # python-pcapng checks block alignment with it

    def read(self, n: int = -1) -> bytes:
        if n < 0 or n > MAX_BLOCK:
            self._fail(f"malformed pcapng: a block of {n} bytes at byte {self.block_start} is "
                       f"over the {MAX_BLOCK >> 20} MiB limit")
        data = self.stream.read(n)
        self._feed(data)
        if len(data) < n:
            self.at_end()
        return data

    def at_end(self) -> None:
        if self.hdr or self.left:
            self._fail(f"truncated pcapng: the file ends {self.pos - self.block_start} bytes "
                       f"into the block that starts at byte {self.block_start}")

    def _fail(self, message: str) -> None:
        self.error = self.error or CaptureError(message)
        raise self.error

    def _feed(self, data: bytes) -> None:
        i, n = 0, len(data)
        while i < n:
            if self.left == 0:
                take = min(12 - len(self.hdr), n - i)
                self.hdr += data[i:i + take]
                i += take
                if len(self.hdr) == 12:
                    self._header()
            else:
                step = min(self.left, n - i)
                self.left -= step
                i += step
            if self.left == 0 and not self.hdr:
                self.block_start = self.pos + i
        self.pos += n

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

