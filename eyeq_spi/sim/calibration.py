"""What the simulated EyeQ reports while a TAC or SPC run is in progress and when it is done
(seed 004 §9.9, §9.11), and the 0x84 intrinsic check it makes (§7.1.3). Pure functions of their
arguments; ``eyeq.py`` decides when.
"""

from __future__ import annotations

import zlib
from typing import Any

from eyeq_spi.codec.bits import BitSignalCodec
from eyeq_spi.codec.init_params import init_message
from eyeq_spi.codec.intrinsic import intrinsic_params_from_eeprom
from eyeq_spi.errors import EyeqError


def fill_calibration(name: str, values: dict[str, Any], now: float, started: float,
                     duration: float, seed: int, tac_error: int | None) -> None:
    """Write EYEQ_TAC_CAL_MSG's ``tacCalParams`` or EYEQ_DYNAMIC_CAL_MSG's
    ``dynamicCalParams`` for a run started at ``started`` that takes ``duration`` seconds: in
    progress, then done with a deterministic "measured" alignment derived from ``seed``."""
    done = now - started >= duration
    frac = min(1.0, (now - started) / max(duration, 1e-9))
    if name == "EYEQ_TAC_CAL_MSG":
        cal = values["tacCalParams"]
        cal["runMode"] = 1
        cal["progress"] = 4 if done else 1
        cal["error"] = (tac_error or 1) if done else 0
    else:
        cal = values["dynamicCalParams"]
        cal["runMode"] = 5
        cal["status"] = 1 if done else 0  # SUCCESS / INIT
        cal["error"] = 3 if done else 0  # OK when done, as scene.py's SPC results (§9.9)
        cal["overallProgress"] = int(frac * 100)
    digest = zlib.crc32(f"{seed}-{name}".encode())
    cal["distYaw"] = (digest & 0x3F) - 32 if done else 0
    cal["distPitch"] = ((digest >> 6) & 0x3F) - 32 if done else 0
    cal["roll"] = ((digest >> 12) & 0xFF) / 1000.0 - 0.128 if done else 0.0
    cal["phYaw"] = cal["distYaw"] * 0.05
    cal["phPitch"] = cal["distPitch"] * 0.05
    if "camHeight" in cal:
        cal["camHeight"] = 1.25
    cal["timestamp_us"] = int(now * 1e6)


def strip_crc(codec: BitSignalCodec, params: bytes) -> bytes:
    """0x84 parameters with ``CRC_from_EEPROM`` zeroed: the intrinsic values compared without
    the CRC the host copied from the EEPROM (§7.1.3)."""
    if "CRC_from_EEPROM" not in codec.signals or len(params) != codec.length:
        return params
    raw = codec.decode_raw(params)
    raw["CRC_from_EEPROM"] = 0
    word = 0
    for sig in codec.variant.signals:
        word |= raw[sig.name] << sig.start
    return word.to_bytes(codec.length, "little")


def expected_intrinsics(eeprom: bytes, sw: str) -> bytes | None:
    """The 0x84 parameters (without their CRC) the host must send for this camera EEPROM;
    None when the release has no 0x84 table (§7.1.3)."""
    try:
        expected = init_message(0x84, sw)
    except EyeqError:
        return None
    if expected.codec is None:
        return None
    return strip_crc(expected.codec, expected.codec.encode(
        intrinsic_params_from_eeprom(eeprom, sw)))
