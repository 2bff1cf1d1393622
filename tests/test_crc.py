from __future__ import annotations

import binascii

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eyeq_spi.crc import CCITT_FALSE, VARIANTS, crc16, crcmod_uses_c_extension, make_crc
from eyeq_spi.errors import UsageError


def test_check_value_is_0x29b1() -> None:
    assert crc16(b"123456789") == 0x29B1
    assert make_crc(CCITT_FALSE, engine="crcmod")(b"123456789") == 0x29B1


@given(st.binary(max_size=300))
def test_binascii_and_crcmod_agree(data: bytes) -> None:
    assert binascii.crc_hqx(data, 0xFFFF) == make_crc(CCITT_FALSE, engine="crcmod")(data)


def test_crcmod_runs_its_c_extension() -> None:
    # A pure-Python fallback would make every codec slow; make_crc warns about it, this fails.
    assert crcmod_uses_c_extension()


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_every_configurable_variant_meets_its_check_value(name: str) -> None:
    v = VARIANTS[name]
    assert make_crc(v, engine="crcmod")(b"123456789") == v.check


def test_binascii_engine_refuses_other_variants() -> None:
    with pytest.raises(UsageError, match="cannot compute CRC-16/KERMIT"):
        make_crc(VARIANTS["CRC-16/KERMIT"], engine="binascii")
    with pytest.raises(UsageError, match="unknown CRC engine"):
        make_crc(CCITT_FALSE, engine="zlib")
