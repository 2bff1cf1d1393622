"""The values of the bring-up (§7.1.3) that the host, the simulated EyeQ, the dissector and the
conformance judges share, each read once from ``specs/``."""

from __future__ import annotations

from typing import Any

from eyeq_spi.catalog.link import spec_file
from eyeq_spi.errors import SpecError

SWITCH_APP_NAME = "SwitchEyeQApplication"
"""The MESP function that restarts the EyeQ in another application (§7.1.1.1.4), by its name in
``specs/mesp.yaml``."""


def _entry(name: str, table: list[dict[str, Any]], key: str, value: object) -> dict[str, Any]:
    found = next((e for e in table if e.get(key) == value), None)
    if found is None:
        raise SpecError(f"specs/{name}: no entry with {key} {value!r}")
    return found


def _read() -> tuple[tuple[int, int], str, int]:
    mesp = spec_file("mesp.yaml")
    switch = _entry("mesp.yaml", mesp["mesp_functions"], "name", SWITCH_APP_NAME)
    fatal = spec_file("enums/eyeq_states.yaml")["enums"]["fatal_error"]["values"]
    intrinsic = _entry("enums/eyeq_states.yaml", fatal, "name", "INTRINSIC_CALIBRATION_MISMATCH")
    return ((int(switch["service"]), int(switch["function"])), str(mesp["mesp"]["eeprom_file"]),
            int(intrinsic["value"]))


def _values(enum: str, *names: str) -> tuple[int, ...]:
    """The values of ``names`` in ``enum`` of ``specs/enums/eyeq_states.yaml``."""
    table = spec_file("enums/eyeq_states.yaml")["enums"][enum]["values"]
    return tuple(int(_entry("enums/eyeq_states.yaml", table, "name", n)["value"]) for n in names)


SWITCH_APP, EEPROM_FILE, FATAL_INTRINSIC = _read()
"""``SWITCH_APP``: (service, function) of Switch EyeQ Application; ``EEPROM_FILE``: the file
the host reads with FFS Read File when the EyeQ reports ``FATAL_INTRINSIC`` (Fatal_Error 22,
the camera EEPROM does not match the intrinsic calibration sent: §7.1.3 steps 4-7)."""

# mainState of Get EyeQ Extended State and Main_State of 0x41 (§7.1.5, M7: DV reports 0xAA)
(PENDING, RUNNING_VISION, BOOT, RUNNING_DV, RUNNING_TAC, RUNNING_SPC, PENDING_VISION, PENDING_TAC,
 PENDING_SPC) = _values("main_state", "PENDING", "RUNNING_VISION", "BOOT", "RUNNING_DV",
                        "RUNNING_TAC", "RUNNING_SPC", "PENDING_VISION", "PENDING_TAC",
                        "PENDING_SPC")
# applicationId of Switch EyeQ Application (§7.1.1.1.4)
APP_VISION, APP_TAC, APP_SPC, APP_DV = _values("eyeq_application", "VISION", "TAC", "SPC", "DV")
