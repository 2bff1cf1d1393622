"""The bench the campaigns run on: host emulator and simulated EyeQ over a memory pair (the
in-process emulator), started from an NVM that already matches the camera, so that every run
begins with the second ignition (no Fatal 22 detour) unless asked otherwise."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from functools import lru_cache

from eyeq_spi.emulator import Emulation, build
from eyeq_spi.faults.channel import FaultProfile, FaultyChannel
from eyeq_spi.host.host import HostConfig
from eyeq_spi.host.machine import HostState
from eyeq_spi.host.nvm import Nvm, NvmData
from eyeq_spi.phy.memory import MemoryAdapter
from eyeq_spi.sim.config import SimConfig

FIRST_IGNITION_LIMIT = 5.0  # virtual seconds a clean first ignition may take to reach vision


@dataclass(frozen=True)
class Scene:
    """How busy the simulated EyeQ's scene is (DASP payload work per message)."""

    objects: int = 8
    signs: int = 4
    light_spots: int = 4


@lru_cache(maxsize=8)
def _matched_nvm(sw: str | None) -> NvmData:
    emu = build(sim_config=SimConfig(sw=sw), host_config=HostConfig(sw=sw), nvm=Nvm(),
                keep_rx_times=False)
    emu.run_for(FIRST_IGNITION_LIMIT, stop=lambda: emu.host.state is HostState.RUNNING_VISION)
    if emu.host.state is not HostState.RUNNING_VISION:
        raise RuntimeError(f"a clean first ignition did not reach vision: {emu.host.problem}")
    return copy.deepcopy(emu.host.nvm.data)


def matched_nvm(sw: str | None = None) -> NvmData:
    """The NVM content a clean first ignition leaves (intrinsics from the camera EEPROM)."""
    return copy.deepcopy(_matched_nvm(sw))


def rig(*, seed: int = 1, sw: str | None = None, scene: Scene | None = None,
          fresh_nvm: bool = False, sim_config: SimConfig | None = None) -> Emulation:
    sc = scene or Scene()
    cfg = sim_config or SimConfig(sw=sw, seed=seed, objects=sc.objects, signs=sc.signs,
                                  light_spots=sc.light_spots)
    emu = build(sim_config=cfg, host_config=HostConfig(sw=sw), nvm=Nvm(), keep_rx_times=False)
    if not fresh_nvm:
        # An in-memory NVM is empty when the host loads it at construction; its content is
        # first read for 0x84 in INIT, so filling it now is the second ignition.
        emu.host.nvm.data = matched_nvm(sw)
    return emu


def adapters(emu: Emulation) -> tuple[MemoryAdapter, MemoryAdapter]:
    """The host's and the EyeQ's end of the memory pair (their ``mangle`` is the fault hook)."""
    ends = [a for _, a in emu.runner.nodes if isinstance(a, MemoryAdapter)]
    if len(ends) != 2 or len(emu.runner.nodes) != 2:
        raise TypeError("the emulation does not run over a memory pair")
    return ends[0], ends[1]


def noisy_link(emu: Emulation, ber: float, seed: int = 1) -> None:
    """Flip the bits of every transfer in both directions with probability ``ber`` each (no
    other fault): a bad cable or connector under an otherwise healthy host and EyeQ."""
    profile = FaultProfile(ber=ber, drop=0.0, duplicate=0.0, reorder=0.0, truncate=0.0)
    host_end, sim_end = adapters(emu)
    host_end.mangle = FaultyChannel(profile, seed * 2)
    sim_end.mangle = FaultyChannel(profile, seed * 2 + 1)
