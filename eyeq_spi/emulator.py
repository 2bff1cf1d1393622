"""Host emulator and simulated EyeQ wired together in one process over an in-memory SPI pair,
in virtual time (tests, ``eyeq-spi demo --virtual-time``) or real time (``eyeq-spi demo``).
The reset line of the host is wired to the simulator's power input."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.host.host import HostConfig, HostEmulator
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.host.scenario import Scenario
from eyeq_spi.phy.memory import memory_pair
from eyeq_spi.runner.virtual import Tap, VirtualRunner
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.sim.eyeq import SimulatedEyeQ
from eyeq_spi.summary import RunningVision

HOST_ALONE = frozenset({0})
"""The host (node 0) acts on no other node but through its reset line, which tells the runner."""


@dataclass
class Emulation:
    host: HostEmulator
    sim: SimulatedEyeQ
    runner: VirtualRunner
    vision: RunningVision = field(default_factory=RunningVision)
    # real time: (perf_counter, virtual time) at the first paced slice; every later slice is
    # paced from it, so the run keeps up with the clock over its whole length
    pace_origin: tuple[float, float] | None = None

    def run_for(self, seconds: float, *, realtime: bool = False,
                stop: Callable[[], bool] | None = None) -> None:
        """Advance ``seconds`` of simulated time in 10 ms slices, tracking Running Vision."""
        end = self.runner.now + seconds
        if realtime and self.pace_origin is None:
            self.pace_origin = (time.perf_counter(), self.runner.now)
        while self.runner.now < end - 1e-12 and not (stop is not None and stop()):
            self.runner.run_until(min(end, self.runner.now + 0.01), realtime=realtime,
                                  pace_origin=self.pace_origin)
            self.vision.update(self.host, self.runner.now)


def build(
    *,
    sim_config: SimConfig | None = None,
    host_config: HostConfig | None = None,
    nvm: Nvm | None = None,
    scenario: Scenario | None = None,
    tap: Tap | None = None,
    keep_rx_times: bool = True,
) -> Emulation:
    sim = SimulatedEyeQ(sim_config)

    def reset_line(now: float) -> None:
        # the host acts on the EyeQ: whatever runner drives them must ask both afresh
        sim.power_up(now)
        emu.runner.touch_all()

    host = HostEmulator(host_config, nvm=nvm, scenario=scenario, reset_line=reset_line,
                        keep_rx_times=keep_rx_times)
    host_end, sim_end = memory_pair()
    # the host's only effect on another node is the reset line, which tells the runner
    emu = Emulation(host, sim, VirtualRunner([(host, host_end), (sim, sim_end)], tap=tap,
                                             self_contained=HOST_ALONE))
    sim.power_up(0.0)
    host.start(0.0)
    return emu


def summary(emu: Emulation, *, interrupted: bool = False) -> dict[str, Any]:
    """The demo's closing summary: the schema every run prints (:mod:`eyeq_spi.summary`)."""
    from eyeq_spi.summary import host_summary

    return host_summary(emu.host, side="demo", elapsed=emu.runner.now, wall=emu.runner.wall_s,
                        cpu=emu.runner.cpu_s, running_since=emu.vision.since,
                        left_running=emu.vision.left, interrupted=interrupted,
                        eyeq=emu.sim)
