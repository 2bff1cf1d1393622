"""What the host sends in INIT and reads at boot (seed 004 §7.1.3, §8.2, §21): the init
messages' parameters from the NVM, the intrinsic parameters of an EEPROM image, and the boot
status it keeps; pure functions, the state machine decides when."""

from __future__ import annotations

import math
from typing import Any

from eyeq_spi.catalog.messages import Catalog
from eyeq_spi.catalog.tables import alignment_nvm
from eyeq_spi.codec.init_params import init_message
from eyeq_spi.codec.intrinsic import eeprom_crc_ok, intrinsic_params_from_eeprom, version_text
from eyeq_spi.errors import LocalProtocolError, SpecError
from eyeq_spi.host.config import STAGE_OF
from eyeq_spi.host.nvm import NvmData
from eyeq_spi.mesp.replies import MespFailure, MespResult


def init_values(stage: int, nvm: NvmData) -> dict[str, float]:
    """The signals of init message ``stage`` from the NVM."""
    if stage == 0x84:
        # empty on first power-up: initial (zero) values. A value that is not a finite number
        # cannot have come from a good EEPROM: leave it out, so the EyeQ reports the mismatch
        # (Fatal 22) and the EEPROM is read again (§7.1.3).
        return {k: v for k, v in nvm.intrinsic.items()
                if isinstance(v, int | float) and math.isfinite(v)}
    if stage == 0x92:  # §21: each stored parameter goes out as its 0x92 signal
        return alignment_nvm().init_values(nvm.alignment)
    return {}


def init_table_missing(stage: int, sw: str, cat: Catalog) -> str | None:
    """Why release ``sw`` has no table for init message ``stage`` (0x84 exists from SW6,
    §7.1.3; TAC and SPC need theirs, §7.1.1.7); None where it has one."""
    try:
        init_message(stage, sw, cat)
    except (SpecError, LocalProtocolError) as exc:
        return str(exc)
    return None


def mode_unavailable(mode: str, sw: str, cat: Catalog) -> str | None:
    """Why ``mode`` (TAC, SPC) cannot be run in release ``sw``; None where it can (or needs no
    init message)."""
    stage = STAGE_OF.get(mode)
    return None if stage is None else init_table_missing(stage, sw, cat)


def stages(sw: str, cat: Catalog, camera_only_aeb: bool) -> list[int]:
    """The init messages of the bring-up in order (§6 flow): 0x84 from NVM where the release
    has its table, 0x78 and 0x79 for a camera-only AEB configuration, then 0x92."""
    out = [] if init_table_missing(0x84, sw, cat) else [0x84]
    if camera_only_aeb:
        out += [0x78, 0x79]
    out.append(0x92)
    return out


def init_request(stage: int, sw: str, cat: Catalog, nvm: NvmData, opaque: bytes
                 ) -> dict[str, Any]:
    """The EventCalibrationTool request carrying init message ``stage``: its signals from the
    NVM, each clamped into its declared range; ``opaque`` for a stage the seed prints no bit
    table for (0x78). Raises ``LocalProtocolError``/``SpecError`` when it cannot be built."""
    msg = init_message(stage, sw, cat)
    if msg.codec is None:
        params = opaque
    else:
        clamped = {}
        for key, value in init_values(stage, nvm).items():
            sig = msg.codec.signals.get(key)
            if sig is not None and math.isfinite(value):
                clamped[key] = min(max(value, sig.min), sig.max)
        params = msg.codec.encode(clamped)
    return {"ct_type": msg.ct_type, "ct_stage": stage, "ct_version": msg.ct_version(params),
            "params": params}


def eeprom_intrinsics(image: bytes, sw: str) -> dict[str, float] | str:
    """The intrinsic parameters of a camera EEPROM image (§7.1.3), or why it is unusable."""
    if not eeprom_crc_ok(image):
        return "camera EEPROM CRC-16 does not match: repair or replace the camera"
    try:
        params = intrinsic_params_from_eeprom(image, sw)
    except (LocalProtocolError, SpecError) as exc:
        return f"EEPROM content unusable: {exc}"
    return {k: float(v) for k, v in params.items()}


def boot_info(fields: dict[str, Any]) -> dict[str, Any]:
    """What the host keeps of EYEQ_BOOT_STATUS_MSG: test bits, EyeQ ID and both versions as
    text."""
    return {"TestResults": fields["TestResults"], "EyeQID": fields["EyeQID"],
            "BootVersion": version_text(bytes(fields["BootVersion"])),
            "ApplicationVersion": version_text(bytes(fields["ApplicationVersion"]))}


def eeprom_verdict(result: MespResult, sw: str, resets: int, max_resets: int
                   ) -> dict[str, float] | str:
    """What the host makes of its read of the camera's EEPROM file (§7.1.3): the intrinsic
    parameters for its NVM, or why it cannot use them (the read failed, the image is bad, or
    ``resets`` EyeQ resets have not cleared the mismatch)."""
    if isinstance(result, MespFailure):
        return f"EEPROM read failed: {result}"
    params = eeprom_intrinsics(result.value.data, sw)
    if isinstance(params, str):
        return params
    if resets >= max_resets:
        return (f"intrinsic calibration still mismatched after {resets} EyeQ resets: repair "
                "or replace the camera")
    return params
