"""A host that gave up (FAILED, BOOT_FAILED) stays quiet for the rest of its ignition cycle; a
new connection to the EyeQ (``eyeq-spi host --reconnect``) is its next ignition cycle: a fresh
bring-up with the same NVM. Host emulator against the simulated EyeQ, in virtual time."""

from __future__ import annotations

from eyeq_spi.emulator import Emulation, build
from eyeq_spi.host.machine import HostEvent, HostState
from eyeq_spi.sim.config import SimConfig

S = HostState


def _new_connection(emu: Emulation) -> None:
    """What live.serve and live.drive do on a new connection: the EyeQ powers up, the host's
    link starts over."""
    now = emu.runner.now
    emu.sim.power_up(now)
    emu.host.link_restarted(now)
    emu.runner.touch_all()


def _sent(emu: Emulation) -> int:
    return sum(emu.host.counters.sent.values())


def test_a_failed_host_stays_quiet_then_the_next_connection_is_a_new_ignition_cycle() -> None:
    emu = build(sim_config=SimConfig(corrupt_eeprom_crc=True))
    emu.run_for(3.0)
    assert emu.host.state is S.FAILED and emu.host.problem
    quiet_from = _sent(emu)
    emu.run_for(2.0)
    assert emu.host.state is S.FAILED and _sent(emu) == quiet_from  # §7.1.3 step 6
    cycles = emu.host.nvm.data.ignition_cycles
    emu.sim.eeprom[0x4C] ^= 0xFF  # the camera was repaired: its EEPROM CRC-16 matches again
    _new_connection(emu)
    last = emu.host.transitions[-1]
    assert (last.src, last.event, last.dst) == (S.FAILED, HostEvent.IGNITION, S.POWER_UP)
    assert emu.host.problem is None
    assert emu.host.nvm.data.ignition_cycles == cycles + 1
    emu.run_for(4.0, stop=lambda: emu.vision.since is not None)
    assert emu.host.state is S.RUNNING_VISION, emu.host.problem


def test_boot_strikes_start_afresh_in_the_next_ignition_cycle() -> None:
    """Three failing boots end the first cycle; in the next one a fourth failing boot is its
    first strike (reset and retry), and the fifth boot is good (a sixth follows the EEPROM
    read of the empty NVM, §7.1.3)."""
    emu = build(sim_config=SimConfig(boot_test_failures=0x0002, boot_failures=4))
    emu.run_for(5.0)
    assert emu.host.state is S.BOOT_FAILED and emu.sim.counters.boots == 3
    _new_connection(emu)
    assert emu.host.transitions[-1].dst is S.POWER_UP and emu.host.problem is None
    emu.run_for(6.0, stop=lambda: emu.vision.since is not None)
    assert emu.vision.since is not None, (emu.host.problem, emu.host.transitions[-3:])
    events = [t.event for t in emu.host.transitions]
    cycle = events[events.index(HostEvent.IGNITION):]
    assert cycle[:3] == [HostEvent.IGNITION, HostEvent.BOOT_BAD, HostEvent.BOOT_OK], cycle
