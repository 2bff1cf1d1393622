"""The simulated EyeQ's sparse serial flash and MESP Compute Hash (§7.1.1.3, APPENDIX F)."""

from __future__ import annotations

import hashlib
import zlib
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eyeq_spi.catalog.messages import catalog
from eyeq_spi.errors import LocalProtocolError
from eyeq_spi.sim.flash import (
    DATASET_EXPLICIT,
    DATASET_FFS,
    DATASET_USER,
    HASH_CRC32,
    HASH_LENGTHS,
    HASH_SHA256,
    MIB,
    RET_BAD_PARAMETERS,
    RET_SUCCESS,
    FlashImage,
    explicit_range,
    flash_examples,
    hash_request,
)

HASHES: dict[int, Callable[[bytes], bytes]] = {
    HASH_CRC32: lambda b: zlib.crc32(b).to_bytes(4, "little"),
    HASH_SHA256: lambda b: hashlib.sha256(b).digest(),
}


@pytest.fixture(scope="module")
def flash64() -> FlashImage:
    return FlashImage(64)


@pytest.fixture(scope="module")
def flash128() -> FlashImage:
    return FlashImage(128)


def materialise(image: FlashImage, start: int, size: int) -> bytes:
    """A few MB at most, read in 1 MiB pieces."""
    assert size <= 8 * MIB
    return b"".join(
        image.read(pos, min(MIB, start + size - pos)) for pos in range(start, start + size, MIB)
    )


def example_sizes(example: dict[str, Any]) -> list[int]:
    return [mb for mb in (64, 128) if f"{mb}MB" in example["applies_to"]]


# -- layout ---------------------------------------------------------------------------------
@pytest.mark.parametrize("mb", [64, 128])
def test_size_and_regions_follow_the_flash_map(mb: int) -> None:
    image = FlashImage(mb)
    assert image.size == mb * MIB
    assert image.regions[0].start == 0
    for a, b in zip(image.regions, image.regions[1:], strict=False):
        assert a.end == b.start  # Appendix F tiles the flash
    assert image.regions[-1].end == image.size
    names = [r.name for r in image.regions]
    assert ("MEST (100 deg)" in names) == (mb == 128)
    assert len(names) == (9 if mb == 64 else 13)


@pytest.mark.parametrize("mb", [64, 128])
def test_each_region_starts_programmed_then_erased(mb: int) -> None:
    image = FlashImage(mb)
    starts = [s for s, _ in image.extents]
    assert starts == [r.start for r in image.regions]
    for (start, length), region in zip(image.extents, image.regions, strict=True):
        assert 4096 <= length <= min(region.size, 256 * 1024)
        assert image.read(start, min(length, 64)) != b"\xff" * min(length, 64)
        if length < region.size:
            tail = min(4096, region.size - length)
            assert image.read(start + length, tail) == b"\xff" * tail


@pytest.mark.parametrize("bad", [0, 32, 63, 256])
def test_unknown_flash_size_is_refused(bad: int) -> None:
    with pytest.raises(LocalProtocolError, match="flash size"):
        FlashImage(bad)


def test_128mb_low_range_holds_the_64mb_image(flash64: FlashImage, flash128: FlashImage) -> None:
    assert flash64.hash(HASH_SHA256, 0, flash64.size) == flash128.hash(
        HASH_SHA256, 0, flash64.size
    )
    assert flash128.hash(HASH_SHA256, flash64.size, flash64.size) != flash64.hash(
        HASH_SHA256, 0, flash64.size
    )


# -- read -----------------------------------------------------------------------------------
def test_read_is_bounded(flash64: FlashImage) -> None:
    assert len(flash64.read(0, MIB)) == MIB
    with pytest.raises(LocalProtocolError, match="1 MiB"):
        flash64.read(0, MIB + 1)
    with pytest.raises(LocalProtocolError, match="outside"):
        flash64.read(flash64.size - 10, 11)
    with pytest.raises(LocalProtocolError, match="outside"):
        flash64.read(-1, 4)
    assert flash64.read(flash64.size - 10, 10) != b""
    assert flash64.read(123, 0) == b""


# -- hash -----------------------------------------------------------------------------------
@pytest.mark.parametrize("hash_type", [HASH_CRC32, HASH_SHA256])
@pytest.mark.parametrize("start, size", [(0, 1), (0, 100), (5000, 3000), (0x180000, 0x1000),
                                         (0x3FFFFF0, 0x10), (0x200000 + 0x3FFFF, 2)])
def test_small_range_hash_matches_read(
    flash64: FlashImage, hash_type: int, start: int, size: int
) -> None:
    data = flash64.read(start, size)
    assert len(data) == size
    assert flash64.hash(hash_type, start, size) == HASHES[hash_type](data)


@pytest.mark.parametrize("hash_type", [HASH_CRC32, HASH_SHA256])
def test_range_across_extent_and_gap_matches_materialised(
    flash64: FlashImage, hash_type: int
) -> None:
    loader, ffs = flash64.region("Boot Loader"), flash64.region("FFS")
    ext_len = dict(flash64.extents)[loader.start]
    start = loader.start + ext_len - 1000  # inside the loader, across its gap, into the FFS
    size = ffs.start + 5000 - start
    data = materialise(flash64, start, size)
    assert data[1000 : 1000 + 16] == b"\xff" * 16
    assert data[-5000:] != b"\xff" * 5000
    assert flash64.hash(hash_type, start, size) == HASHES[hash_type](data)
    # a gap longer than the 1 MiB erased block, with an odd tail
    mest = flash64.region("MEST")
    data = materialise(flash64, mest.start + 17, 3 * MIB + 12345)
    assert flash64.hash(hash_type, mest.start + 17, 3 * MIB + 12345) == HASHES[hash_type](data)


def test_whole_image_hash_streams_like_reads(flash64: FlashImage) -> None:
    crc = 0
    for pos in range(0, flash64.size, MIB):
        crc = zlib.crc32(flash64.read(pos, MIB), crc)
    assert flash64.hash(HASH_CRC32, 0, flash64.size) == crc.to_bytes(4, "little")


@pytest.mark.parametrize("mb", [64, 128])
def test_whole_image_hash_is_stable(mb: int) -> None:
    # (its speed is measured in tools/bench.py, not asserted here)
    image = FlashImage(mb, seed=7)
    first = {ht: image.hash(ht, 0, image.size) for ht in HASH_LENGTHS}
    assert {ht: len(v) for ht, v in first.items()} == HASH_LENGTHS
    again = FlashImage(mb, seed=7)
    for ht, value in first.items():
        assert image.hash(ht, 0, image.size) == value
        assert again.hash(ht, 0, again.size) == value


def test_hash_refuses_bad_arguments(flash64: FlashImage) -> None:
    with pytest.raises(LocalProtocolError, match="hash type"):
        flash64.hash(2, 0, 16)
    with pytest.raises(LocalProtocolError, match="outside"):
        flash64.hash(HASH_CRC32, flash64.size - 1, 2)


def test_seed_determines_content() -> None:
    a, b, c = FlashImage(64, seed=1), FlashImage(64, seed=1), FlashImage(64, seed=2)
    loader = a.region("Boot Loader")
    for ht in HASH_LENGTHS:
        assert a.hash(ht, loader.start, loader.size) == b.hash(ht, loader.start, loader.size)
        assert a.hash(ht, loader.start, loader.size) != c.hash(ht, loader.start, loader.size)
    assert a.extents == b.extents


WINDOW = 3 * MIB  # Secure Boot, Boot Manager, Boot Loader, both FFS and the start of MEST


@given(probes=st.lists(
    st.tuples(st.integers(0, WINDOW - 1), st.integers(1, 600000)), min_size=1, max_size=4))
def test_reads_and_hashes_agree_with_a_dense_model(probes: list[tuple[int, int]]) -> None:
    image = FlashImage(64, seed=3)
    model = materialise(image, 0, WINDOW)
    for start, size in probes:
        size = min(size, WINDOW - start)
        chunk = bytes(model[start : start + size])
        assert image.read(start, size) == chunk
        for ht, fn in HASHES.items():
            assert image.hash(ht, start, size) == fn(chunk)


# -- MESP Compute Hash ----------------------------------------------------------------------
def test_ret_codes_match_decision_m2() -> None:
    rets = catalog().mesp_ret
    assert rets[RET_SUCCESS] == "SUCCESS"
    assert rets[RET_BAD_PARAMETERS] == "BAD_PARAMETERS"


def test_every_seed_example_hashes(flash64: FlashImage, flash128: FlashImage) -> None:
    examples = flash_examples()
    assert len(examples) == 2
    images = {64: flash64, 128: flash128}
    for ex in examples:
        sizes = example_sizes(ex)
        assert sizes, ex["name"]
        for mb in sizes:
            for ht in (ex["hash_type"], HASH_SHA256):
                ret, result = hash_request(
                    images[mb], ht, ex["dataset_type"], ex["start"], ex["size"]
                )
                assert ret == RET_SUCCESS, (ex["name"], mb)
                assert len(result) == HASH_LENGTHS[ht]


def test_example_ranges_follow_the_decision(flash64: FlashImage, flash128: FlashImage) -> None:
    by_name = {ex["name"][:9]: ex for ex in flash_examples()}
    a, b = by_name["Example A"], by_name["Example B"]
    # A fits: a byte count, one byte short of EDR; the same bytes on both flash sizes
    assert explicit_range(64 * MIB, a["start"], a["size"]) == (0, 0x3DFFFFF)
    ret64 = hash_request(flash64, HASH_CRC32, DATASET_EXPLICIT, a["start"], a["size"])
    ret128 = hash_request(flash128, HASH_CRC32, DATASET_EXPLICIT, a["start"], a["size"])
    assert ret64 == ret128 == (RET_SUCCESS, flash64.hash(HASH_CRC32, 0, 0x3DFFFFF))
    # B would run past 128 MB: an inclusive end address, the whole high range
    assert explicit_range(128 * MIB, b["start"], b["size"]) == (0x4000000, 0x4000000)
    assert hash_request(flash128, HASH_CRC32, DATASET_EXPLICIT, b["start"], b["size"]) == (
        RET_SUCCESS, flash128.hash(HASH_CRC32, 0x4000000, 0x4000000))
    # B on a 64 MB flash starts past its end
    assert hash_request(flash64, HASH_CRC32, DATASET_EXPLICIT, b["start"], b["size"]) == (
        RET_BAD_PARAMETERS, b"")


@pytest.mark.parametrize(
    "hash_type, dataset_type, start, size",
    [
        (2, DATASET_EXPLICIT, 0, 16),          # unknown hash type
        (255, DATASET_EXPLICIT, 0, 16),
        (-1, DATASET_EXPLICIT, 0, 16),
        (HASH_CRC32, 3, 0, 16),                # unknown dataset type
        (HASH_CRC32, 255, 0, 16),
        (HASH_CRC32, DATASET_EXPLICIT, 0, 0),  # size 0
        (HASH_CRC32, DATASET_EXPLICIT, 0x4000000, 1),          # start at the end
        (HASH_CRC32, DATASET_EXPLICIT, 0x3FFFFFF, 2),          # one byte past the end
        (HASH_CRC32, DATASET_EXPLICIT, 0x3000000, 0x1800000),  # runs past, size < start
        (HASH_CRC32, DATASET_EXPLICIT, 0x100, 0x4000000),      # runs past, size not an address
        (HASH_CRC32, DATASET_EXPLICIT, 0, 0x100000000),        # not a u32
        (HASH_CRC32, DATASET_EXPLICIT, -1, 16),
    ],
)
def test_bad_parameters(
    flash64: FlashImage, hash_type: int, dataset_type: int, start: int, size: int
) -> None:
    assert hash_request(flash64, hash_type, dataset_type, start, size) == (
        RET_BAD_PARAMETERS, b"")


@pytest.mark.parametrize("hash_type", [HASH_CRC32, HASH_SHA256])
def test_good_explicit_requests(flash64: FlashImage, hash_type: int) -> None:
    assert hash_request(flash64, hash_type, DATASET_EXPLICIT, 0x3FFFFFF, 1) == (
        RET_SUCCESS, HASHES[hash_type](flash64.read(0x3FFFFFF, 1)))
    assert hash_request(flash64, hash_type, DATASET_EXPLICIT, 0, flash64.size) == (
        RET_SUCCESS, flash64.hash(hash_type, 0, flash64.size))
    # runs past the end but names an address inside it: inclusive end
    assert hash_request(flash64, hash_type, DATASET_EXPLICIT, 0x100, 0x3FFFFFF) == (
        RET_SUCCESS, flash64.hash(hash_type, 0x100, 0x4000000 - 0x100))


@pytest.mark.parametrize("mb", [64, 128])
def test_predefined_datasets_ignore_start_and_size(mb: int) -> None:
    image = FlashImage(mb)
    ffs, edr = image.region("FFS"), image.region("EDR")
    assert ffs.start == 0x180000 and edr.start == 0x3E00000  # the first of each in Appendix F
    for start, size in [(0, 0), (0x123, 0x456)]:
        assert hash_request(image, HASH_SHA256, DATASET_FFS, start, size) == (
            RET_SUCCESS, HASHES[HASH_SHA256](image.read(ffs.start, ffs.size)))
        assert hash_request(image, HASH_CRC32, DATASET_USER, start, size) == (
            RET_SUCCESS, image.hash(HASH_CRC32, 0, edr.start))
