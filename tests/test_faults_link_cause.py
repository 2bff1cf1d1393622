"""A bad link is not a bad camera: when the link's own counters explain a failed bring-up,
the transition and the summary name the link, with its figures."""

from __future__ import annotations

import pytest

from eyeq_spi.emulator import summary
from eyeq_spi.faults.rig import noisy_link, rig
from eyeq_spi.host.link_health import LIKELY
from eyeq_spi.host.machine import HostState
from eyeq_spi.sim.config import SimConfig


@pytest.mark.parametrize("seed", [1, 2])
def test_a_noisy_link_is_named_as_the_likely_cause(seed: int) -> None:
    emu = rig(seed=seed)
    noisy_link(emu, ber=1e-3, seed=seed)  # about 64 % of the frames hit
    emu.run_for(10.0)
    out = summary(emu)
    assert not out["ok"] and LIKELY in out["problem"], out["problem"]
    assert "frames received corrupt" in out["problem"]
    if emu.host.state in (HostState.BOOT_FAILED, HostState.FAILED):  # the host gave up
        assert LIKELY in emu.host.transitions[-1].detail, emu.host.transitions[-1]


def test_a_camera_that_fails_its_boot_on_a_clean_link_is_the_camera() -> None:
    emu = rig(sim_config=SimConfig(boot_failures=10, boot_test_failures=0x0001))
    emu.run_for(10.0)
    assert emu.host.state is HostState.BOOT_FAILED
    problem = summary(emu)["problem"]
    assert "boot failed 3 times" in problem and LIKELY not in problem, problem
