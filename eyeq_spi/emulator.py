"""Host emulator and simulated EyeQ wired together in one process over an in-memory SPI pair,
in virtual time (tests, ``eyeq-spi demo --virtual-time``) or real time (``eyeq-spi demo``).
The reset line of the host is wired to the simulator's power input."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.host.host import HostConfig, HostEmulator
from eyeq_spi.host.machine import HostState
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.host.scenario import Scenario
from eyeq_spi.phy.memory import memory_pair
from eyeq_spi.runner.virtual import Tap, VirtualRunner
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.sim.eyeq import SimulatedEyeQ

HOST_ALONE = frozenset({0})
"""The host (node 0) acts on no other node but through its reset line, which tells the runner."""


@dataclass
class Emulation:
    host: HostEmulator
    sim: SimulatedEyeQ
    runner: VirtualRunner
    running_since: float | None = None
    left_running: list[float] = field(default_factory=list)

    def run_for(self, seconds: float, *, realtime: bool = False,
                stop: Callable[[], bool] | None = None) -> None:
        """Advance ``seconds`` of simulated time in 10 ms slices, tracking Running Vision."""
        end = self.runner.now + seconds
        while self.runner.now < end - 1e-12 and not (stop is not None and stop()):
            self.runner.run_until(min(end, self.runner.now + 0.01), realtime=realtime)
            self._track()

    def _track(self) -> None:
        running = self.host.state is HostState.RUNNING_VISION
        if running and self.running_since is None:
            self.running_since = self.runner.now
        elif not running and self.running_since is not None:
            self.left_running.append(self.runner.now)
            self.running_since = None


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
    made: list[Emulation] = []

    def reset_line(now: float) -> None:
        # the host acts on the EyeQ: whatever runner drives them must ask both afresh
        sim.power_up(now)
        for emu in made:
            emu.runner.touch_all()

    host = HostEmulator(host_config, nvm=nvm, scenario=scenario, reset_line=reset_line,
                        keep_rx_times=keep_rx_times)
    a, b = memory_pair()
    # the host's only effect on another node is the reset line, which tells the runner
    runner = VirtualRunner([(host, a), (sim, b)], tap=tap, self_contained=HOST_ALONE)
    sim.power_up(0.0)
    host.start(0.0)
    made.append(Emulation(host, sim, runner))
    return made[0]


def summary(emu: Emulation) -> dict[str, Any]:
    """The demo's closing JSON object."""
    host = emu.host
    names = [m.name for m in host.codec.cat.messages if m.exists_in(host.sw) or
             m.protocol != "DASP"]
    messages = {n: int(host.counters.received.get(n, 0)) for n in names}
    messages["HOST_VEH_STATE_MSG"] = int(host.counters.sent.get("HOST_VEH_STATE_MSG", 0))
    link = host.conn.link.counters.seed_view()
    return {
        "state": host.state.value,
        "virtual_s": round(emu.runner.now, 6),
        "wall_s": round(emu.runner.wall_s, 3),
        "cpu_s": round(emu.runner.cpu_s, 3),
        "sw": host.sw,
        "messages": messages,
        "link": link,
        "transport_aborts": dict(host.conn.counters.transferAborts),
        "e2e_errors": host.counters.e2e_errors,
        "dasp_counter_gaps": host.counters.dasp_counter_gaps,
        "decode_errors": host.counters.decode_errors,
        "stale_streams": sorted(host.stale_streams),
        "mesp": {"requests": host.mesp.counters.requests, "retries": host.mesp.counters.retries,
                 "timeouts": host.mesp.counters.timeouts,
                 "stale_replies": host.mesp.counters.stale_replies},
        "eyeq_resets": host.counters.eyeq_resets,
        "versions": host.versions,
        "boot": host.boot_info,
        "problem": host.problem,
        "transitions": [
            {"t": round(t.time, 4), "from": t.src.value, "event": t.event.value,
             "to": t.dst.value} for t in host.transitions
        ],
        "running_vision_since": None if emu.running_since is None
        else round(emu.running_since, 4),
    }
