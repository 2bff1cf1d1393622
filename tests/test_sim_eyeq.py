"""The simulated EyeQ steps its scene once per camera frame (§7.1.4: every vision
message runs at 18 Hz) and every DASP message of a frame is filled from that one state."""

from __future__ import annotations

import math
from typing import Any

from eyeq_spi.emulator import build
from eyeq_spi.host.machine import HostState
from eyeq_spi.sim.config import SimConfig


def test_scene_steps_once_per_camera_frame_and_messages_share_it() -> None:
    emu = build(sim_config=SimConfig(objects=15, signs=20, light_spots=15), keep_rx_times=False)
    emu.run_for(1.0)
    assert emu.host.state is HostState.RUNNING_VISION
    sim, scene = emu.sim, emu.sim.scene
    steps: list[float] = []
    fills: list[tuple[float, float | None]] = []
    step, fill = scene.step, sim._fill

    def counting_step(t: float, ego_speed: float | None = None,
                      yaw_rate: float | None = None) -> None:
        steps.append(t)
        step(t, ego_speed, yaw_rate)

    def recording_fill(name: str, values: dict[str, Any], now: float) -> None:
        fills.append((now, scene.world._t))
        fill(name, values, now)

    scene.step = counting_step  # type: ignore[method-assign]
    sim._fill = recording_fill  # type: ignore[method-assign]
    emu.run_for(2.0)
    rate = sim.config.dasp_rate
    assert 2.0 * rate - 2 <= len(steps) <= 2.0 * rate + 2  # not once per message (~12 per frame)
    assert len(fills) > 5 * len(steps)
    frames = [math.floor(t * rate + 1e-6) for t in steps]
    assert frames == sorted(set(frames))  # one step per frame, in order
    for now, t in fills:  # each message reads the state of the frame it is sent in
        assert t is not None and math.isclose(t, math.floor(now * rate + 1e-6) / rate)
