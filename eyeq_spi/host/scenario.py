"""Vehicle signals for HOST_VEH_STATE_MSG: a constant-speed drive, or a CSV of signals (a
``time`` column in seconds and ``host_vehicle_state_t`` member names; each row holds until the
next, the last forever)."""

from __future__ import annotations

import bisect
import csv
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

from eyeq_spi.errors import InputError
from eyeq_spi.host.config import VALID


class Scenario(Protocol):
    def signals(self, time_s: float) -> dict[str, float]: ...


class ConstantDrive:
    def __init__(self, speed: float = 25.0, yaw_rate: float = 0.0) -> None:
        if not math.isfinite(speed) or not math.isfinite(yaw_rate):
            raise InputError("speed and yaw rate must be finite")
        self.speed = speed
        self.yaw_rate = yaw_rate

    def signals(self, time_s: float) -> dict[str, float]:
        return {"vehicleVelocity": self.speed, "vehicleYawRate": self.yaw_rate}


class CsvScenario:
    def __init__(self, path: str | Path, allowed: set[str] | None = None) -> None:
        self.path = Path(path)
        try:
            text = self.path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{self.path}: cannot read scenario: {exc}") from exc
        rows = list(csv.reader(text.splitlines()))
        if not rows or "time" not in rows[0]:
            raise InputError(f"{self.path}: first row must be a header with a 'time' column")
        header = [h.strip() for h in rows[0]]
        unknown = [h for h in header if h != "time" and allowed is not None and h not in allowed]
        if unknown:
            raise InputError(f"{self.path}: unknown signal column(s) {unknown}")
        self.times: list[float] = []
        self.rows: list[dict[str, float]] = []
        for lineno, row in enumerate(rows[1:], start=2):
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) != len(header):
                raise InputError(f"{self.path}:{lineno}: {len(row)} fields, header has "
                                 f"{len(header)}")
            try:
                values = {h: float(c) for h, c in zip(header, row, strict=True)}
            except ValueError as exc:
                raise InputError(f"{self.path}:{lineno}: {exc}") from None
            if not all(math.isfinite(v) for v in values.values()):
                raise InputError(f"{self.path}:{lineno}: values must be finite")
            time_s = values.pop("time")
            if self.times and time_s < self.times[-1]:
                raise InputError(f"{self.path}:{lineno}: time goes backwards")
            self.times.append(time_s)
            self.rows.append(values)
        if not self.rows:
            raise InputError(f"{self.path}: no data rows")

    def signals(self, time_s: float) -> dict[str, float]:
        row = bisect.bisect_right(self.times, time_s) - 1
        return dict(self.rows[max(row, 0)])


def veh_state_values(values: dict[str, Any], signals: Mapping[str, float], now: float,
                     api: tuple[int, int], rolling: int) -> dict[str, Any]:
    """Fill a ``zero_values()`` dict of HOST_VEH_STATE_MSG (any release): the scenario's
    signals, every validity flag but the OBS ones set, the time stamps, our API version and
    ``SPI_Rolling_Count`` (echoed by the EyeQ in 0xA0)."""
    vs = values["vehStateInfo"]
    for key, value in signals.items():
        if key in vs:
            vs[key] = value
    for key in list(vs):
        if key.endswith("Validity") and not key.startswith("OBS"):
            vs[key] = 1
    if "timestamp_us" in vs:
        vs["timestamp_us"] = int(now * 1e6)
    if "apiVersionMajor" in vs:
        vs["apiVersionMajor"], vs["apiVersionMinor"] = api
    values["SPI_Rolling_Count"] = rolling
    if "host_sync_timestamp_us_valid" in values:
        values["host_sync_timestamp_us_valid"] = VALID
        values["host_sync_timestamp_us"] = int(now * 1e6)
    return values
