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


def read_pcapng(fh: IO[bytes]) -> Iterator[Record]:
    """Stream the transfers of a pcapng capture. Malformed files raise :class:`CaptureError`."""
    from pcapng import FileScanner, blocks
    from pcapng.exceptions import PcapngException

    names: dict[int, str | None] = {}
    scales: dict[int, float] = {}
    try:
        for block in FileScanner(fh):
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
    except (PcapngException, struct.error, EOFError, ValueError, KeyError) as exc:
        raise CaptureError(f"malformed pcapng: {exc}") from None
    except Exception as exc:
        raise CaptureError(f"malformed pcapng ({type(exc).__name__}: {exc})") from None
