"""Regression tests for the defects the fault campaign found. Each failed
before its fix; defect 1 (splice across a peer reset) is in tests/test_dissect_engine.py."""

from __future__ import annotations

import os
import struct
import time
from pathlib import Path

import pytest

from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.intrinsic import eeprom_codec, seal_eeprom
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.emulator import build
from eyeq_spi.errors import LocalProtocolError
from eyeq_spi.host.host import HostConfig
from eyeq_spi.host.machine import HostState
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.link import LinkConfig
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.sim.eyeq import SimulatedEyeQ
from eyeq_spi.transport import TransportConnection

S = HostState


@pytest.mark.parametrize("value", [float("nan"), float("inf"), 1e6])
def test_crc_valid_eeprom_with_unusable_value_is_a_camera_fault(value: float) -> None:
    """Defect 2: a CRC-valid EEPROM whose CCAM_distorParams_m_0 cannot be encoded sent the host
    into a LocalProtocolError crash in _send_init. Now: FAILED, with a problem naming the field."""
    emu = build()
    sig = eeprom_codec().signals["CCAM_distorParams_m_0"]
    image = bytearray(emu.sim.eeprom)
    image[sig.start // 8: sig.start // 8 + 4] = struct.pack("<f", value)
    emu.sim.eeprom[:] = seal_eeprom(bytes(image))
    emu.run_for(3.0)
    assert emu.host.state is S.FAILED
    assert emu.host.problem is not None and "CCAM_distorParams_m_0" in emu.host.problem


def _veh_state_transfers(velocity: float, *, break_crc: bool) -> list[bytes]:
    mc = MessageCodec()
    msg = mc.message("HOST_VEH_STATE_MSG")
    values = mc.layout(msg).zero_values()
    vs = values["vehStateInfo"]
    vs["vehicleVelocity"] = velocity
    for k in vs:
        if k.endswith("Validity"):
            vs[k] = 1
    wire = bytearray(mc.encode_dasp(msg.name, values, 0, E2EState()))
    if break_crc:  # D5: vehicleVelocity is covered by crc_16; change it, keep the CRC
        i = bytes(wire).index(struct.pack("<f", velocity))
        wire[i:i + 4] = struct.pack("<f", velocity + 1.0)
    tx = TransportConnection(LinkConfig(role="host"))
    tx.send(bytes(wire), 0.0)
    out: list[bytes] = []
    for i in range(50):
        out += tx.data_to_send(i * 0.001)
    return out


def _running_sim() -> SimulatedEyeQ:
    sim = SimulatedEyeQ(SimConfig(objects=15, signs=20, light_spots=15))
    sim.power_up(0.0)
    sim.handle_timer(0.3)
    sim.main_state, sim.sub_state = 0x02, 0  # Running Vision: DASP and the scene run
    return sim


@pytest.mark.parametrize("velocity", [3.4e38, 1e30, float("inf"), -1e9])
def test_huge_vehicle_velocity_never_makes_a_step_unbounded(velocity: float) -> None:
    """Defect 3: the scene looped forever in _extend_road/_update_road on a huge velocity."""
    sim = _running_sim()
    for t in _veh_state_transfers(velocity, break_crc=False):
        sim.receive_data(t, 0.31)
    t0 = time.process_time()
    for i in range(40):
        sim.handle_timer(0.32 + i * 0.01)
    assert time.process_time() - t0 < 10.0  # bounded (it never returned before the fix)
    assert sim.counters.rejected_values == 1  # outside the seed's -20..100 m/s: not used


def test_rejected_veh_state_structure_never_drives_the_scene() -> None:
    """Defect 3: the values of a HOST_VEH_STATE_MSG whose E2E CRC failed were used."""
    sim = _running_sim()
    for t in _veh_state_transfers(12.5, break_crc=True):
        sim.receive_data(t, 0.31)
    assert sim.counters.e2e_errors == 1
    assert sim._ego == (None, None)


def test_switching_to_tac_on_a_release_without_its_table_is_refused_not_a_crash() -> None:
    """Defect 4: with SW 6, switching to TAC crashed the host with a SpecError."""
    emu = build(sim_config=SimConfig(sw="6"), host_config=HostConfig(sw="6"))
    emu.run_for(3.0)
    assert emu.host.state is S.RUNNING_VISION
    with pytest.raises(LocalProtocolError, match="TAC is not available for SW"):
        emu.host.switch_mode("TAC", emu.runner.now)
    emu.run_for(0.5)
    assert emu.host.state is S.RUNNING_VISION


@pytest.mark.parametrize("reset_at", [0.531, 0.533, 0.537, 0.542])
def test_reset_right_after_entering_running_vision_recovers(reset_at: float) -> None:
    """Defect 5: a reset 1-7 ms after Running Vision, before any 0x41 said Main_State 2, lost
    the boot status to out-of-window NAKs and the host stayed in RUNNING_VISION with no DASP."""
    emu = build(sim_config=SimConfig(reset_at=reset_at))
    emu.run_for(6.0)
    assert emu.host.counters.eyeq_resets >= 1
    assert emu.host.state is S.RUNNING_VISION and not emu.host.stale_streams
    assert emu.sim.main_state == 0x02


def test_stale_nvm_temp_files_are_removed_and_never_read(tmp_path: Path) -> None:
    """Defect 6: killed writes left temp files behind."""
    path = tmp_path / "nvm.json"
    nvm = Nvm(path)
    nvm.save()
    dead = tmp_path / f".nvm.json.{2**22 + 12345}.abc123.nvm-tmp"  # a PID that cannot exist
    old = tmp_path / ".nvm.json.k3j4h5g6"  # the pre-0.2 mkstemp name
    live = tmp_path / f".nvm.json.{os.getppid()}.zz.nvm-tmp"  # a live writer's file
    other = tmp_path / ".nvm.json.notes"
    for f in (dead, old, live, other):
        f.write_text("{not json")
    again = Nvm(path)
    again.load()
    assert again.load_problem is None and again.removed_temp_files == 2
    assert not dead.exists() and not old.exists() and live.exists() and other.exists()


def test_soft_reset_restarts_the_eyeqs_e2e_judgement() -> None:
    """Found by tools/soak_live.py: after the host's soft reset (Switch Application vision, no
    reset line) its rolling counters start afresh; the restarted EyeQ application must not count
    that as an E2E error."""
    sim = _running_sim()
    for t in _veh_state_transfers(12.5, break_crc=False):
        sim.receive_data(t, 0.31)
    assert sim._switch_app({"applicationId": 0x01})[0] == 0  # the MESP handler
    sim.conn.reset()  # a fresh sender below numbers its frames from 0 again
    for t in _veh_state_transfers(12.5, break_crc=False):
        sim.receive_data(t, 0.40)
    assert sim.counters.e2e_errors == 0


def test_a_soft_reset_leaves_the_host_rolling_counters_unbroken_for_a_passive_reader() -> None:
    """Live runs (no reset line): after Fatal 22 the host soft-resets the EyeQ with Switch EyeQ
    Application. Its HOST_VEH_STATE E2E rolling counters used to restart there while its DASP
    counter ran on, so `dissect` of a normal first-ignition capture reported an E2E counter jump.
    Our own counters now run on across EyeQ resets, as the DASP counter does."""
    from eyeq_spi.capture.pcapng_io import Transfer
    from eyeq_spi.dissect.engine import Dissector
    from eyeq_spi.host.host import HostEmulator
    from eyeq_spi.phy.memory import memory_pair
    from eyeq_spi.runner.virtual import VirtualRunner

    sim = SimulatedEyeQ(SimConfig())
    host = HostEmulator(HostConfig(), nvm=Nvm())  # no reset line: a remote EyeQ
    a, b = memory_pair()
    seen: list[Transfer] = []
    runner = VirtualRunner([(host, a), (sim, b)], tap=lambda node, t, x: seen.append(
        Transfer(t, "h2e" if node == 0 else "e2h", x)))
    sim.power_up(0.0)
    host.start(0.0)
    runner.run_until(2.0)
    assert host.state is HostState.RUNNING_VISION
    assert host.counters.sent["HOST_VEH_STATE_MSG"] > 20
    assert sim.counters.e2e_errors == 0
    dis = Dissector()
    out = [r for rec in seen for r in dis.feed(rec)]
    switches = [r for r in out if r.get("name") == "SwitchEyeQApplication"]
    veh = [r for r in out if r.get("name") == "HOST_VEH_STATE_MSG"]
    assert switches and veh[0]["time"] < switches[0]["time"]  # the case: sent before the reset
    assert [r["errors"] for r in veh if r["errors"]] == []


@pytest.mark.parametrize("exact_path", [False, True])
@pytest.mark.parametrize(("member", "value"), [
    ("vehicleVelocity", 1e39),  # beyond real32
    ("vehIndex", 1e39),  # a float into a uint32
    ("vehIndex", -1.0),
])
def test_a_scenario_value_the_message_cannot_carry_is_a_host_problem_not_a_crash(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    exact_path: bool, member: str, value: float,
) -> None:
    """A scenario CSV value that HOST_VEH_STATE_MSG cannot encode stopped the run with an
    internal error (an OverflowError or struct.error out of the encoder on either path, then a
    TypeError in the host's timer): the host now reports the problem and demo exits 1."""
    from eyeq_spi.cli import main

    if exact_path:
        monkeypatch.setenv("EYEQ_SPI_EXACT", "1")
    else:
        monkeypatch.delenv("EYEQ_SPI_EXACT", raising=False)
    csv = tmp_path / "s.csv"
    csv.write_text(f"time,{member}\n0,10\n0.5,{value!r}\n")
    rc = main(["demo", "--virtual-time", "--duration", "1.5", "--scenario", str(csv)])
    out, err = capsys.readouterr()
    assert rc == 1, err
    assert "HOST_VEH_STATE_MSG cannot be encoded" in out and "internal error" not in err


@pytest.mark.parametrize("exact_path", [False, True])
def test_both_encoders_refuse_unencodable_values_with_a_codec_error(
    monkeypatch: pytest.MonkeyPatch, exact_path: bool,
) -> None:
    from eyeq_spi.errors import LocalProtocolError

    monkeypatch.setenv("EYEQ_SPI_EXACT", "1" if exact_path else "0")
    codec = MessageCodec()
    lay = codec.layout(codec.message("HOST_VEH_STATE_MSG"))
    for member, value in (("vehicleVelocity", 1e39), ("vehIndex", 1e39), ("vehIndex", -1),
                          ("vehIndex", 1 << 40), ("vehicleVelocity", "fast")):
        values = lay.zero_values()
        values["vehStateInfo"][member] = value
        with pytest.raises(LocalProtocolError, match="cannot encode"):
            lay.build(values)
