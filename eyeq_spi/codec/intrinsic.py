"""Intrinsic calibration (seed 004 §7.1.3, Appendix E, decision I2): the EEPROM image, its CRC,
and the 0x84 parameters the host derives from it."""

from __future__ import annotations

from functools import cache
from typing import Any

from eyeq_spi.codec.bits import BitSignalCodec
from eyeq_spi.crc import crc16
from eyeq_spi.errors import LocalProtocolError

CRC_SIGNAL = "CameraCalibrationCRC"  # the CRC-16 of the calibration block before it (I2)


@cache
def crc_slice() -> slice:
    """Where the EEPROM image holds its CRC-16 (0x4C..0x4D, little-endian; specs/init, I2):
    the calibration block is every byte before it."""
    signal = eeprom_codec().signals[CRC_SIGNAL]
    return slice(signal.start // 8, (signal.start + signal.length) // 8)


def eeprom_crc(image: bytes) -> int:
    crc_at = crc_slice()
    if len(image) < crc_at.stop:
        raise LocalProtocolError(f"EEPROM image of {len(image)} bytes has no CRC at "
                                 f"0x{crc_at.start:02X}")
    return crc16(image[:crc_at.start])


def eeprom_crc_ok(image: bytes) -> bool:
    """True when the CRC-16 at 0x4C matches the calibration block (§7.1.3 step 5)."""
    crc_at = crc_slice()
    if len(image) < crc_at.stop:
        return False
    return int.from_bytes(image[crc_at], "little") == crc16(image[:crc_at.start])


def seal_eeprom(image: bytes) -> bytes:
    """Write the correct CRC-16 at 0x4C."""
    sealed = bytearray(image)
    sealed[crc_slice()] = eeprom_crc(image).to_bytes(2, "little")
    return bytes(sealed)


def normalise_num_distor_params(count: int) -> int:
    """§7.1.3: 3 or 7 read from EEPROM is stored and sent as 7; 11 or 15 as 15."""
    if count in (3, 7):
        return 7
    if count in (11, 15):
        return 15
    raise LocalProtocolError(f"CCAM_Num_Of_distorParams_m = {count}: the seed defines only "
                             "3, 7, 11 and 15")


def eeprom_codec() -> BitSignalCodec:
    return BitSignalCodec.for_message("EEPROM_DATA")


def default_eeprom_image() -> bytes:
    """Appendix E's example EEPROM, with its CRC."""
    return seal_eeprom(eeprom_codec().encode())


def intrinsic_params_from_eeprom(image: bytes, sw: str | None = None) -> dict[str, Any]:
    """The 0x84 signal values (physical) for an EEPROM image, normalised per §7.1.3."""
    ee = eeprom_codec().decode(image[: eeprom_codec().length])
    target = BitSignalCodec.for_message("Init_Intrinsic_Calibration", sw)
    out: dict[str, Any] = {}
    for name in target.signals:
        if name in ee and not name.startswith("Reserved"):
            out[name] = ee[name]
    count = int(out.get("CCAM_Num_Of_distorParams_m", 0))
    out["CCAM_Num_Of_distorParams_m"] = normalise_num_distor_params(count)
    for name, value in out.items():
        # §7.1.3: a CRC-valid EEPROM can still hold values the 0x84 message cannot carry
        # (NaN, infinity, out of range): a camera fault that names the field
        try:
            target.to_raw(target.signals[name], value)
        except LocalProtocolError as exc:
            raise LocalProtocolError(f"EEPROM field {name}: {exc}") from None
    if "CRC_from_EEPROM" in target.signals:
        out["CRC_from_EEPROM"] = int.from_bytes(image[crc_slice()], "little")
    return out


def version_bytes(version: str) -> bytes:
    """§7.1.5.3: "Boot version 7.1.23 -> 0x07 0x01 0x17 0x00" (byte 3 reserved)."""
    parts = version.split(".")
    if len(parts) != 3:
        raise LocalProtocolError(f"version {version!r} is not MAJOR.MINOR.PATCH")
    try:
        nums = [int(p) for p in parts]
    except ValueError:
        raise LocalProtocolError(f"version {version!r} is not numeric") from None
    if not all(0 <= n <= 255 for n in nums):
        raise LocalProtocolError(f"version {version!r}: each number must be 0..255")
    return bytes([*nums, 0])


def version_text(data: bytes) -> str:
    if len(data) != 4:
        raise LocalProtocolError("a version field is 4 bytes")
    return f"{data[0]}.{data[1]}.{data[2]}"
