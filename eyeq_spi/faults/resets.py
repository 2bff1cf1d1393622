"""Reset campaign: the simulated EyeQ resets at a seeded random moment of Running Vision (through
its public ``power_up``, as the reset line would, without telling the host); within
``recovery_limit`` the host must report the reset (an ``EYEQ_RESET`` transition), reach Running
Vision again and hold it for ``hold`` seconds with no stale DASP stream, and deliver no message
with an EyeQ ``timestamp_ms`` from before the reset, nor any outside a running state. A quarter
of the offsets fall in the first 50 ms of Running Vision, where a reset meets messages still in
flight; the rest are uniform over ``max_offset``."""

from __future__ import annotations

import random
from dataclasses import asdict, dataclass, field
from typing import Any

from eyeq_spi.codec.message import DecodedMessage
from eyeq_spi.faults.rig import Scene, rig
from eyeq_spi.host.machine import HostEvent, HostState

EARLY_SHARE = 0.25
EARLY_WINDOW = 0.050
RUNNING_VISION_MAIN_STATE = 0x02
RUNNING = (HostState.RUNNING_VISION, HostState.RUNNING_TAC, HostState.RUNNING_SPC)


@dataclass(frozen=True)
class ResetConfig:
    max_offset: float = 2.0  # seconds of Running Vision before the reset, at most
    recovery_limit: float = 3.0  # seconds from the reset to Running Vision again
    hold: float = 0.3  # seconds Running Vision must then hold (> 3 DASP periods: stale check)
    bring_up_limit: float = 5.0
    sw: str | None = None
    scene: Scene = field(default_factory=Scene)


@dataclass
class ResetOutcome:
    seed: int
    offset: float
    reset_at: float | None
    noticed_at: float | None  # the host's EYEQ_RESET transition
    back_at: float | None  # Running Vision again
    recovered: bool
    stale_deliveries: int
    host_state: str
    eyeq_main_state: int
    stale_streams: list[str]
    problem: str | None

    @property
    def ok(self) -> bool:
        return self.recovered and self.stale_deliveries == 0


def reset_offset(seed: int, max_offset: float) -> float:
    """Seconds of Running Vision before the reset of run ``seed``."""
    rng = random.Random(seed)
    early = rng.random() < EARLY_SHARE
    return rng.uniform(0.0, EARLY_WINDOW if early else max_offset)


def _timestamp_ms(fields: dict[str, Any]) -> int | None:
    """The EyeQ timestamp of a DASP payload (top level or one struct down), if it has one."""
    if "timestamp_ms" in fields:
        return int(fields["timestamp_ms"])
    for value in fields.values():
        if isinstance(value, dict) and "timestamp_ms" in value:
            return int(value["timestamp_ms"])
    return None


def run_reset(seed: int, config: ResetConfig | None = None) -> ResetOutcome:
    cfg = config or ResetConfig()
    offset = reset_offset(seed, cfg.max_offset)
    emu = rig(seed=seed, sw=cfg.sw, scene=cfg.scene)
    host, sim = emu.host, emu.sim
    emu.run_for(cfg.bring_up_limit, stop=lambda: host.state is HostState.RUNNING_VISION)
    if host.state is not HostState.RUNNING_VISION:
        return ResetOutcome(seed, offset, None, None, None, False, 0, host.state.value,
                            sim.main_state, sorted(host.stale_streams),
                            f"no Running Vision before the reset: {host.problem}")
    delivered: list[tuple[float, int | None, HostState]] = []

    def on_message(msg: DecodedMessage) -> None:
        delivered.append((emu.runner.now, _timestamp_ms(msg.fields), host.state))

    host.subscribe(on_message)
    emu.run_for(offset)
    reset_at = emu.runner.now
    sim.power_up(reset_at)  # what the reset line does, behind the host's back
    seen = len(host.transitions)

    def noticed() -> float | None:
        return next((t.time for t in host.transitions[seen:]
                     if t.event is HostEvent.EYEQ_RESET), None)

    def back() -> float | None:
        noticed_at = noticed()
        if noticed_at is None:
            return None
        return next((t.time for t in host.transitions[seen:]
                     if t.dst is HostState.RUNNING_VISION and t.time >= noticed_at), None)

    emu.run_for(cfg.recovery_limit, stop=lambda: back() is not None)
    back_at = back()
    if back_at is not None:
        emu.run_for(cfg.hold)
    noticed_at = noticed()
    held = (back_at is not None and host.state is HostState.RUNNING_VISION
            and len([t for t in host.transitions[seen:] if t.time > back_at]) == 0)
    recovered = (held and sim.main_state == RUNNING_VISION_MAIN_STATE
                 and not host.stale_streams)
    reset_ms = int(reset_at * 1000)
    stale = sum(1 for t, ts, state in delivered
                if state not in RUNNING
                or (noticed_at is not None and t >= noticed_at and ts is not None
                    and ts <= reset_ms))
    return ResetOutcome(seed, offset, reset_at, noticed_at, back_at, recovered, stale,
                        host.state.value, sim.main_state, sorted(host.stale_streams),
                        host.problem)


@dataclass
class CampaignReport:
    runs: int
    recovered: int
    stale_runs: int
    stale_deliveries: int
    failures: list[dict[str, Any]]
    wall_s: float = 0.0

    @property
    def ok(self) -> bool:
        return self.recovered == self.runs and self.stale_runs == 0

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "ok": self.ok}


def summarise(outcomes: list[ResetOutcome], wall_s: float = 0.0) -> CampaignReport:
    bad = [o for o in outcomes if not o.ok]
    return CampaignReport(
        runs=len(outcomes), recovered=sum(o.recovered for o in outcomes),
        stale_runs=sum(o.stale_deliveries > 0 for o in outcomes),
        stale_deliveries=sum(o.stale_deliveries for o in outcomes),
        failures=[asdict(o) for o in bad], wall_s=round(wall_s, 3))
