"""The host's init-message and EEPROM helpers (eyeq_spi/host/init_seq.py, §7.1.3, §21)."""

from __future__ import annotations

import math

from eyeq_spi.codec.init_params import init_message
from eyeq_spi.codec.intrinsic import default_eeprom_image
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.host import init_seq
from eyeq_spi.host.nvm import NvmData


def test_eeprom_intrinsics_reads_a_good_image_and_names_a_bad_one() -> None:
    sw = MessageCodec().sw
    good = init_seq.eeprom_intrinsics(default_eeprom_image(), sw)
    assert isinstance(good, dict) and good
    assert all(isinstance(v, float) for v in good.values())
    broken = bytearray(default_eeprom_image())
    broken[10] ^= 0xFF
    assert "CRC-16 does not match" in str(init_seq.eeprom_intrinsics(bytes(broken), sw))
    assert "CRC-16 does not match" in str(init_seq.eeprom_intrinsics(bytes(8), sw))


def test_init_request_drops_non_finite_values_and_clamps_into_range() -> None:
    codec = MessageCodec()
    msg = init_message(0x84, codec.sw, codec.cat)
    assert msg.codec is not None
    name, sig = next(iter(msg.codec.signals.items()))
    other = list(msg.codec.signals)[1]
    nvm = NvmData(intrinsic={name: sig.max * 10 + 1000, other: math.nan})
    assert init_seq.init_values(0x84, nvm) == {name: sig.max * 10 + 1000}
    req = init_seq.init_request(0x84, codec.sw, codec.cat, nvm, b"\0")
    assert req["ct_stage"] == 0x84
    assert msg.codec.decode(req["params"])[name] == sig.max


def test_an_init_stage_without_a_table() -> None:
    codec = MessageCodec()
    assert init_seq.init_table_missing(0x92, codec.sw, codec.cat) is None
    assert init_seq.init_table_missing(0x84, "4.0", codec.cat)
