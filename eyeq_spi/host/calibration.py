"""When a TAC or SPC run has finished, and whether it succeeded (§9.9, §9.11, §21): the
``success`` row of the §21 Alignment NVM table in ``specs/nvm.yaml``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from eyeq_spi.catalog.messages import Catalog, SwKey
from eyeq_spi.catalog.tables import alignment_nvm
from eyeq_spi.errors import SpecError


def enum_value(cat: Catalog, enum: str, name: str) -> int:
    for entry in cat.enums[enum].values.values():
        if entry.name == name:
            return entry.value
    raise SpecError(f"enum {enum} has no value {name}")


def member_value(cat: Catalog, sw: SwKey, struct: str, member: str, name: str) -> int:
    """The value of enum value ``name`` of ``struct.member`` in release ``sw``."""
    var = cat.structs[struct].variant_for(sw)
    member_def = next((m for m in var.members if m.name == member), None) if var else None
    if member_def is None or member_def.enum is None:
        raise SpecError(f"{struct}.{member} is not an enum in SW {sw}")
    return enum_value(cat, member_def.enum, name)


def outcome(cat: Catalog, sw: SwKey, mode: str, cal: Mapping[str, Any]) -> bool | None:
    """None while the ``mode`` run (TAC or SPC) is still going, else whether it succeeded."""
    if mode == "TAC":
        if cal["progress"] != enum_value(cat, "static_cal_progress", "RESULTS_READY"):
            return None
    elif cal["status"] == enum_value(cat, "dynamic_cal_status", "INIT"):
        return None
    source = alignment_nvm().source(mode)
    return all(cal.get(member) == member_value(cat, sw, source.result, member, name)
               for member, name in source.success.items())


def result(cat: Catalog, sw: SwKey, mode: str, cal: Mapping[str, Any],
           now: float) -> dict[str, Any] | None:
    """None while the ``mode`` run is still going; else what the host reports of it
    (``HostEmulator.calibration_result``): the mode, whether it succeeded, when, and the angles
    the result carries."""
    ok = outcome(cat, sw, mode, cal)
    if ok is None:
        return None
    return {"mode": mode, "ok": ok, "time": now, **{
        k: cal[k] for k in ("distYaw", "distPitch", "roll", "phYaw", "phPitch") if k in cal}}
