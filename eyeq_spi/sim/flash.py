"""The simulated EyeQ's serial flash and MESP Compute Hash (0x03/0x11, §7.1.1.3, decision M3).

The flash is 64 MB or 128 MB laid out as APPENDIX F (``specs/flash_map.yaml``), never
materialised: each region holds one extent of deterministic pseudo-random content at its start
(SHAKE-256 of ``seed``, the region's name and address; the 128 MB flash's low range holds the
64 MB flash's bytes) over an erased background of 0xFF, and ``hash()`` streams over extents and
gaps, so the whole 128 MB hashes in well under a second.

The "size" field of an EXPLICIT request (decision, recorded in ``specs/flash_map.yaml``)
---------------------------------------------------------------------------------------
The request table (§7.1.1.3, seed line 633) defines the field as "Block size (in bytes) to compute
(from start address)", but both of the seed's examples print a value that reads as an inclusive
end address (lines 639-659): Example A ``start 0x0, size 0x3DFFFFF`` (the last byte before EDR),
Example B ``start 0x4000000, size 0x7FFFFFF`` (the last byte of a 128 MB flash). One request can
only mean one thing, so ``explicit_range`` resolves ``(start, size)`` like this:

1. ``size == 0`` or ``start`` outside the flash: bad parameters (ret 3).
2. ``start + size <= flash size``: the table's reading, ``size`` bytes from ``start`` (Example A
   hashes 0x0..0x3DFFFFE, one byte short of the customer sector's end).
3. Otherwise, if ``start <= size < flash size``, ``size`` is read as the inclusive end address:
   ``size + 1 - start`` bytes (Example B on a 128 MB flash).
4. Anything else runs past the flash: bad parameters (Example B on a 64 MB flash).

Other datasets ignore ``start`` and ``size`` (line 633: "Relevant only for EXPLICIT_DATASET").
The seed does not say what USER_DATASET's predefined set is; the simulated EyeQ uses the low
range Example A means, from address 0 up to the first EDR region. FFS_DATASET is the first FFS
region of the map (on a 128 MB flash, the 52 deg one)."""

from __future__ import annotations

import hashlib
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from typing import Any, Final

from eyeq_spi.catalog.link import spec_file
from eyeq_spi.errors import LocalProtocolError, SpecError

# §7.1.1.3 request "Hash type" enum
HASH_SHA256: Final = 0
HASH_CRC32: Final = 1
HASH_LENGTHS: Final = {HASH_SHA256: 32, HASH_CRC32: 4}

# §7.1.1.3 request "Data set type" enum
DATASET_EXPLICIT: Final = 0
DATASET_USER: Final = 1
DATASET_FFS: Final = 2

# decision M2 (specs/mesp.yaml `mesp_ret`)
RET_SUCCESS: Final = 0
RET_BAD_PARAMETERS: Final = 3

MIB: Final = 1 << 20
READ_LIMIT: Final = MIB  # read() is for small reads; hash() streams
U32_MAX: Final = 0xFFFFFFFF

_ERASED: Final = 0xFF
_ERASED_BLOCK: Final = bytes([_ERASED]) * MIB

# content per region: between 1/64 and 1/4 of the region, clamped to 4 KB .. 256 KB
_CONTENT_MIN: Final = 4 * 1024
_CONTENT_MAX: Final = 256 * 1024


@dataclass(frozen=True)
class FlashRegion:
    """One row of APPENDIX F."""

    name: str
    start: int
    size: int

    @property
    def end(self) -> int:
        return self.start + self.size

    @property
    def base_name(self) -> str:
        """The component without its camera qualifier: ``"FFS (52 deg)"`` -> ``"FFS"``."""
        return self.name.split(" (", 1)[0]


def _flash_map() -> dict[str, Any]:
    fmap = spec_file("flash_map.yaml").get("flash_map")
    if not isinstance(fmap, dict):
        raise SpecError("specs/flash_map.yaml: no `flash_map` mapping")
    return fmap


def flash_sizes_mb() -> tuple[int, ...]:
    """The flash sizes APPENDIX F describes (64 and 128)."""
    return tuple(int(x) for x in _flash_map().get("sizes_mb", ()))


@cache
def flash_regions(size_mb: int) -> tuple[FlashRegion, ...]:
    """APPENDIX F for one flash size, sorted by address and checked to tile inside the flash."""
    regions = sorted((FlashRegion(str(r["name"]), int(r["start"]), int(r["size"]))
                      for r in _flash_map().get("regions", ())
                      if int(r.get("flash_mb", 0)) == size_mb), key=lambda r: r.start)
    total = size_mb * MIB
    pos = 0
    for region in regions:
        if region.size <= 0 or region.start < pos or region.end > total:
            raise SpecError(f"flash_map.yaml: {size_mb}MB region {region.name!r} overlaps or "
                            "overflows")
        pos = region.end
    return tuple(regions)


def flash_examples() -> list[dict[str, Any]]:
    """The §7.1.1.3 Compute Hash example requests recorded in ``flash_map.yaml``."""
    return list(_flash_map().get("examples", ()))


def _content(seed: int, region: FlashRegion) -> bytes:
    # base name: the 128 MB low range holds the same content as the 64 MB flash
    key = f"eyeq-spi flash {seed} {region.base_name} {region.start:#x}".encode()
    digest = hashlib.sha256(key).digest()
    frac = int.from_bytes(digest[:4], "little") / 2**32  # 0 .. 1
    share = region.size // 64 + int(frac * (region.size // 4 - region.size // 64))
    length = min(region.size, max(_CONTENT_MIN, min(_CONTENT_MAX, share)))
    return hashlib.shake_256(digest).digest(length)


class FlashImage:
    """A sparse serial flash image: populated extents over erased (0xFF) background."""

    def __init__(self, size_mb: int = 64, seed: int = 1) -> None:
        sizes = flash_sizes_mb()
        if size_mb not in sizes:
            raise LocalProtocolError(
                f"flash size {size_mb} MB is not in APPENDIX F (expected one of {sizes})"
            )
        self.size_mb = size_mb
        self.size = size_mb * MIB
        self.seed = seed
        self.regions: list[FlashRegion] = list(flash_regions(size_mb))
        # one (start, content) extent per region, in address order
        self._extents = [(region.start, _content(seed, region)) for region in self.regions]

    # -- lookup ------------------------------------------------------------------------------
    def region(self, name: str) -> FlashRegion:
        """The first region called ``name`` (exactly, or ignoring the camera qualifier)."""
        for region in self.regions:
            if name in (region.name, region.base_name):
                return region
        raise LocalProtocolError(f"no region {name!r} in the {self.size_mb}MB flash map")

    @property
    def extents(self) -> list[tuple[int, int]]:
        """``(start, length)`` of every populated extent, in address order."""
        return [(start, len(data)) for start, data in self._extents]

    def _check_range(self, start: int, size: int, what: str) -> None:
        if start < 0 or size < 0 or start + size > self.size:
            raise LocalProtocolError(
                f"{what} [{start:#x}, {start + size:#x}) is outside the "
                f"{self.size_mb}MB flash [0x0, {self.size:#x})"
            )

    def _segments(self, start: int, end: int) -> Iterator[bytes | memoryview]:
        """The bytes of ``[start, end)`` as a stream of extent slices and erased blocks."""
        pos = start
        for ext_start, data in [*self._extents, (end, b"")]:
            ext_end = min(end, ext_start + len(data))
            if ext_end <= pos:
                continue
            while pos < min(ext_start, end):  # the erased gap before the extent
                size = min(MIB, ext_start - pos, end - pos)
                yield _ERASED_BLOCK if size == MIB else memoryview(_ERASED_BLOCK)[:size]
                pos += size
            if pos < ext_end:
                yield memoryview(data)[pos - ext_start:ext_end - ext_start]
                pos = ext_end
            if pos >= end:
                return

    # -- access ------------------------------------------------------------------------------
    def read(self, start: int, size: int) -> bytes:
        """``size`` bytes from ``start``; at most 1 MiB (use ``hash()`` for large ranges)."""
        if size > READ_LIMIT:
            raise LocalProtocolError(f"read of {size:#x} bytes refused: read() is limited to 1 MiB")
        self._check_range(start, size, "read")
        return b"".join(bytes(s) for s in self._segments(start, start + size))

    def hash(self, hash_type: int, start: int, size: int) -> bytes:
        """CRC32 (zlib, 4 bytes LE) or SHA-256 (32 bytes) of ``[start, start + size)``."""
        self._check_range(start, size, "hash range")
        segments = self._segments(start, start + size)
        if hash_type == HASH_CRC32:
            crc = 0
            for seg in segments:
                crc = zlib.crc32(seg, crc)
            return crc.to_bytes(4, "little")
        if hash_type == HASH_SHA256:
            digest = hashlib.sha256()
            for seg in segments:
                digest.update(seg)
            return digest.digest()
        raise LocalProtocolError(f"unknown hash type {hash_type} (0 SHA-256, 1 CRC32)")


# -- MESP Compute Hash ----------------------------------------------------------------------
def explicit_range(flash_size: int, start: int, size: int) -> tuple[int, int] | None:
    """``(start, byte count)`` an EXPLICIT request covers, or None for bad parameters (the
    module docstring's rules)."""
    if not (0 <= start <= U32_MAX and 0 <= size <= U32_MAX) or size == 0 or start >= flash_size:
        return None
    if start + size <= flash_size:
        return start, size
    if start <= size < flash_size:  # §7.1.1.3 Example B: an inclusive end address
        return start, size + 1 - start
    return None


def dataset_range(
    image: FlashImage, dataset_type: int, start: int, size: int
) -> tuple[int, int] | None:
    """``(start, byte count)`` a Compute Hash request covers, or None for bad parameters."""
    if dataset_type == DATASET_EXPLICIT:
        return explicit_range(image.size, start, size)
    if dataset_type == DATASET_USER:  # predefined set: the low range, up to EDR
        return 0, image.region("EDR").start
    if dataset_type == DATASET_FFS:  # the flash file system block
        ffs = image.region("FFS")
        return ffs.start, ffs.size
    return None


def hash_request(
    image: FlashImage, hash_type: int, dataset_type: int, start: int, size: int
) -> tuple[int, bytes]:
    """Answer MESP Compute Hash: ``(ret, result)``, ret 0 or 3 (decision M2), result b"" on 3."""
    if hash_type not in HASH_LENGTHS:
        return RET_BAD_PARAMETERS, b""
    rng = dataset_range(image, dataset_type, start, size)
    if rng is None:
        return RET_BAD_PARAMETERS, b""
    return RET_SUCCESS, image.hash(hash_type, *rng)
