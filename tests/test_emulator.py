"""Host emulator against the simulated EyeQ, in virtual time."""

from __future__ import annotations

import itertools
import math
import statistics
from pathlib import Path

import pytest

from eyeq_spi.emulator import build, summary
from eyeq_spi.host import init_seq
from eyeq_spi.host.host import HostConfig
from eyeq_spi.host.machine import HostState
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.host.scenario import CsvScenario
from eyeq_spi.sim.config import SimConfig

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

S = HostState


def path(emu) -> list[str]:  # type: ignore[no-untyped-def]
    return [t.dst.value for t in emu.host.transitions]


def test_normal_bring_up_reaches_running_vision_and_holds(tmp_path: Path) -> None:
    nvm = Nvm(tmp_path / "nvm.json")
    emu = build(nvm=nvm)
    emu.run_for(3.0)
    # first power-up: empty NVM -> zeros in 0x84 -> Fatal 22 -> EEPROM -> NVM -> reset
    assert S.READ_EEPROM.value in path(emu)
    assert emu.host.state is S.RUNNING_VISION, (emu.host.problem, path(emu))
    emu2 = build(nvm=Nvm(tmp_path / "nvm.json"))  # next ignition: NVM already right
    emu2.run_for(3.0)
    assert path(emu2) == ["WAIT_PENDING", "INIT", "WAIT_RUNNING", "RUNNING_VISION"]
    out = summary(emu2)
    assert out["e2e_errors"] == 0 and out["dasp_counter_gaps"] == 0 and not out["stale_streams"]
    assert out["versions"] == {"apiVersionMajor": 9, "apiVersionMinor": 0,
                               "eyeqSwVersionMajor": 9, "eyeqSwVersionMinor": 0}
    assert emu2.sim.counters.calibration_events == [(0x84, 0), (0x92, 0)]
    assert emu2.host.nvm.data.ignition_cycles == 2


def test_first_power_up_goes_through_fatal_22_and_writes_nvm(tmp_path: Path) -> None:
    nvm_file = tmp_path / "nvm.json"
    emu = build(nvm=Nvm(nvm_file))
    emu.run_for(4.0)
    p = path(emu)
    i = p.index("READ_EEPROM")
    assert p[i + 1] == "POWER_UP" and p[-1] == "RUNNING_VISION"
    nvm = Nvm(nvm_file).load()
    assert nvm.intrinsic["CCAM_Num_Of_distorParams_m"] == 15  # Appendix E's 11 -> 15 (§7.1.3)
    assert nvm.intrinsic["CCAM_camK1_FocalLengthX_m"] == 24041 * 0.0625
    assert emu.sim.counters.boots == 2 and emu.sim.fatal_error == 0


def test_corrupt_eeprom_crc_ends_in_failed() -> None:
    emu = build(sim_config=SimConfig(corrupt_eeprom_crc=True))
    emu.run_for(3.0)
    assert emu.host.state is S.FAILED
    assert "repair or replace" in (emu.host.problem or "")
    assert emu.host.nvm.writes == 0


def test_boot_test_failure_three_strikes() -> None:
    emu = build(sim_config=SimConfig(boot_test_failures=0x0002, boot_failures=99))
    emu.run_for(5.0)
    assert emu.host.state is S.BOOT_FAILED
    assert emu.sim.counters.boots == 3 and emu.host.counters.boot_failures == 3
    assert "3 times" in (emu.host.problem or "")


def test_boot_failure_then_recovery_resets_the_strike_count() -> None:
    emu = build(sim_config=SimConfig(boot_test_failures=0x0010, boot_failures=2))
    emu.run_for(5.0)
    assert emu.sim.counters.boots >= 3
    assert emu.host.state is S.RUNNING_VISION


@pytest.fixture
def running(tmp_path: Path):  # type: ignore[no-untyped-def]
    emu = build(nvm=Nvm(tmp_path / "nvm.json"))
    emu.run_for(3.0)
    assert emu.host.state is S.RUNNING_VISION
    return emu


@pytest.mark.parametrize(("mode", "state", "roll_kept"), [("TAC", S.RUNNING_TAC, True),
                                                           ("SPC", S.RUNNING_SPC, False)])
def test_tac_and_spc_round_trips_update_nvm(running, mode: str, state: HostState,  # type: ignore[no-untyped-def]
                                            roll_kept: bool) -> None:
    emu = running
    emu.host.switch_mode(mode, emu.runner.now)
    emu.run_for(1.0)
    assert emu.host.state is state
    assert emu.host.counters.sent["HOST_VEH_STATE_MSG"] > 0
    sent_before = emu.host.counters.sent["HOST_VEH_STATE_MSG"]
    emu.run_for(3.0)
    assert emu.host.counters.sent["HOST_VEH_STATE_MSG"] == sent_before  # DASP stopped
    result = emu.host.calibration_result
    assert result is not None and result["ok"] and result["mode"] == mode
    a = emu.host.nvm.data.alignment
    assert a["cameraAlignmentValidKA"] == 1
    assert (a["horizonKA"], a["yawKA"]) == (result["distPitch"], result["distYaw"])
    if roll_kept:
        assert a["rollAngleKA"] == pytest.approx(result["roll"])
    else:
        assert a["rollAngleKA"] == 0.0  # §21: SPC sets rollAngleKA to 0
    emu.host.switch_mode("VISION", emu.runner.now)
    emu.run_for(2.0)
    assert emu.host.state is S.RUNNING_VISION
    assert (0x85 if mode == "TAC" else 0x82, 0) in emu.sim.counters.calibration_events


def test_init_0x92_carries_the_stored_alignment_as_section_21_says(running) -> None:  # type: ignore[no-untyped-def]
    """§21 via specs/nvm.yaml: horizonKA -> horizonFull, yawKA -> yawFull, rollAngleKA (degrees,
    as TAC measures roll) -> rollAngle in radians, cameraAlignmentValidKA ->
    cameraAlignmentValid."""
    host = running.host
    host.nvm.data.alignment = {"horizonKA": 3.0, "yawKA": -4.0, "rollAngleKA": 2.0,
                               "cameraAlignmentValidKA": 1.0}
    assert init_seq.init_values(0x92, host.nvm.data) == pytest.approx(
        {"horizonFull": 3.0, "yawFull": -4.0, "rollAngle": math.radians(2.0),
         "cameraAlignmentValid": 1.0})


def test_a_failed_calibration_leaves_the_nvm_alone(running) -> None:  # type: ignore[no-untyped-def]
    emu = running
    emu.sim.config.tac_error = 2  # TARGET_NOT_FOUND
    before = dict(emu.host.nvm.data.alignment)
    emu.host.switch_mode("TAC", emu.runner.now)
    emu.run_for(4.0)
    result = emu.host.calibration_result
    assert result is not None and result["mode"] == "TAC" and not result["ok"]
    assert emu.host.nvm.data.alignment == before


def test_dv_mode(running) -> None:  # type: ignore[no-untyped-def]
    running.host.switch_mode("DV", running.runner.now)
    running.run_for(1.0)
    assert running.host.state is S.DV and running.sim.main_state == 0xAA  # M7: RUNNING_DV


def test_eyeq_reset_in_running_vision_recovers_without_stale_delivery(tmp_path: Path) -> None:
    Nvm(tmp_path / "nvm.json")
    build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)  # first ignition writes NVM
    emu = build(nvm=Nvm(tmp_path / "nvm.json"), sim_config=SimConfig(reset_at=4.0))
    delivered: list[tuple[float, str, HostState]] = []
    emu.host.subscribe(lambda m: delivered.append((emu.runner.now, m.name or "", emu.host.state)))
    emu.run_for(8.0)
    assert emu.host.counters.eyeq_resets == 1
    assert emu.host.state is S.RUNNING_VISION
    assert all(state in (S.RUNNING_VISION,) for _, _, state in delivered)
    reset_t = next(t.time for t in emu.host.transitions if t.event.value == "EYEQ_RESET")
    back = [t.time for t in emu.host.transitions if t.dst is S.RUNNING_VISION]
    assert back[-1] > reset_t
    assert not [d for d in delivered if reset_t <= d[0] < back[-1]]


def test_mesp_timeout_retry_and_late_reply_is_dropped(tmp_path: Path) -> None:
    build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)
    emu = build(nvm=Nvm(tmp_path / "nvm.json"),
                sim_config=SimConfig(delay_replies={"GetEyeQVersions": 0.6}))
    emu.run_for(1.5)  # first reply arrives late, the retry's too (0.6 s each)
    c = emu.host.mesp.counters
    assert c.timeouts >= 1 and c.retries >= 1 and c.stale_replies >= 1
    emu.run_for(3.0)
    assert emu.host.state is S.RUNNING_VISION


def test_dropped_replies_are_retried_under_a_new_tag(tmp_path: Path) -> None:
    build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)
    emu = build(nvm=Nvm(tmp_path / "nvm.json"),
                sim_config=SimConfig(drop_replies={"GetEyeQVersions": 1}))
    emu.run_for(3.0)
    assert emu.host.mesp.counters.retries == 1 and emu.host.mesp.counters.stale_replies == 0
    assert emu.host.versions is not None


def _rates(times: list[float]) -> list[float]:
    return [b - a for a, b in itertools.pairwise(times)]


def test_rates_over_60_seconds(tmp_path: Path) -> None:
    build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)
    emu = build(nvm=Nvm(tmp_path / "nvm.json"))
    emu.run_for(63.0)
    assert emu.host.state is S.RUNNING_VISION and not emu.vision.left
    t0 = emu.vision.since
    assert t0 is not None
    rx = emu.host.counters.rx_times
    for name in ("EYEQ_VIS_OBSTACLES_MSG", "EYEQ_BASE_DIAG_STATUS_MSG", "EYEQ_VIS_ROAD_DATA_MSG"):
        gaps = _rates([t for t in rx[name] if t > t0 + 0.5])
        assert len(gaps) >= 18 * 59
        assert statistics.mean(gaps) == pytest.approx(1 / 18, abs=1e-3)
        assert max(abs(g - 1 / 18) for g in gaps) <= 0.010, name  # 18 Hz ± 10 ms
    diag = _rates([t for t in rx["EYEQ_DIAGNOSTIC_MSG"] if t > t0])
    assert statistics.mean(diag) == pytest.approx(1 / 37, abs=1e-3)
    assert min(g - 1 / 37 for g in diag) >= -0.025 and max(g - 1 / 37 for g in diag) <= 0.050
    tx = _rates([t for t in emu.host.counters.tx_times if t > t0])
    assert statistics.mean(tx) == pytest.approx(1 / 66.67, abs=1e-4)
    assert max(abs(g - 1 / 66.67) for g in tx) <= 0.005  # 66.67 Hz ± 5 ms
    out = summary(emu)
    assert out["e2e_errors"] == 0 and out["link"]["sendFailedErrorCounter"] == 0


def test_stale_stream_is_detected(tmp_path: Path) -> None:
    build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)
    emu = build(nvm=Nvm(tmp_path / "nvm.json"),
                sim_config=SimConfig(stop_dasp={"EYEQ_VIS_SRP_MSG": 4.0}))
    emu.run_for(5.0)
    assert emu.host.stale_streams == {"EYEQ_VIS_SRP_MSG"}
    assert emu.host.counters.stale_events["EYEQ_VIS_SRP_MSG"] == 1


def test_fatal_error_stops_dasp_expectations(tmp_path: Path) -> None:
    build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)
    emu = build(nvm=Nvm(tmp_path / "nvm.json"))
    emu.run_for(3.0)
    emu.sim.config.fatal_error = 11
    emu.run_for(1.0)
    assert emu.host.state is S.FATAL and not emu.host.stale_streams


def test_base_diag_reflects_what_the_sim_received(running) -> None:  # type: ignore[no-untyped-def]
    got = []
    running.host.subscribe(lambda m: got.append(m) if m.name == "EYEQ_BASE_DIAG_STATUS_MSG"
                           else None)
    running.run_for(1.0)
    last = got[-1].fields
    # the snapshot was taken when 0xA0 was sent; the live counter may have moved on since
    assert 0 < last["eyeqSPIMsg20RxCtr"] <= running.sim.counters.msg20_rx
    assert running.sim.counters.msg20_rx - last["eyeqSPIMsg20RxCtr"] <= 4  # 66.67 vs 18 Hz
    assert abs(last["SPI_Rolling_Count_Echo"] - running.host.veh_state.rolling) <= 5
    assert last["eyeqSPIMsgRxBadHdrCtr"] == 0 and last["eyeqSPIMsgRxBadSeqCtr"] == 0


def test_async_iterator_delivers_messages(running) -> None:  # type: ignore[no-untyped-def]
    import asyncio

    it = running.host.messages()
    running.run_for(0.5)

    async def take() -> list[str]:
        return [(await it.__anext__()).name for _ in range(5)]

    names = asyncio.run(take())
    assert len(names) == 5 and all(n for n in names)


def test_csv_scenario_drives_vehicle_state(tmp_path: Path) -> None:
    csv = tmp_path / "drive.csv"
    csv.write_text("time,vehicleVelocity,vehicleYawRate\n0,10,0\n2,20,0.05\n")
    build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)
    emu = build(nvm=Nvm(tmp_path / "nvm.json"), scenario=CsvScenario(csv))
    seen: list[float] = []
    orig = emu.sim._on_dasp

    def spy(data: bytes, now: float) -> None:
        orig(data, now)
        out = emu.sim.codec.decode(data)
        if out.name == "HOST_VEH_STATE_MSG":
            seen.append(out.fields["vehStateInfo"]["vehicleVelocity"])

    emu.sim._on_dasp = spy  # type: ignore[method-assign]
    emu.run_for(4.0)
    assert 10.0 in seen and 20.0 in seen


def test_camera_only_aeb_sends_ipb_and_pcw_before_vision(tmp_path: Path) -> None:
    build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)
    emu = build(nvm=Nvm(tmp_path / "nvm.json"), host_config=HostConfig(camera_only_aeb=True))
    emu.run_for(3.0)
    assert [s for s, _ in emu.sim.counters.calibration_events] == [0x84, 0x78, 0x79, 0x92]
    assert emu.host.state is S.RUNNING_VISION


def test_bad_init_parameters_get_nonzero_ret(running) -> None:  # type: ignore[no-untyped-def]
    from eyeq_spi.codec.init_params import init_message

    msg = init_message(0x92)
    assert msg.codec is not None
    bad = bytearray(msg.codec.encode())
    bad[10] = 0xFF  # cameraHeight raw far out of range
    ret, _ = running.sim._calibration({"ct_type": 3, "ct_stage": 0x92, "ct_version": 1,
                                       "params": bytes(bad)})
    assert ret == 3


def test_architecture_state_diagram_is_generated_from_the_table() -> None:
    from eyeq_spi.host.machine import diagram

    readme = (Path(__file__).resolve().parents[1] / "docs" / "architecture.md").read_text()
    assert "```mermaid\n" + diagram() + "\n```" in readme


def _mesp(emu, function: str, params: dict):  # type: ignore[no-untyped-def]
    results: list = []
    emu.host.mesp.request(function, params, now=emu.runner.now, callback=results.append)
    emu.run_for(0.2, stop=lambda: bool(results))
    assert results, f"no result for {function}"
    return results[0]


def test_compute_hash_over_the_link_on_the_appendix_f_examples(running) -> None:  # type: ignore[no-untyped-def]
    import yaml

    from eyeq_spi.catalog.link import specs_dir
    from eyeq_spi.mesp.replies import MespFailure, MespReply

    examples = yaml.safe_load((specs_dir() / "flash_map.yaml").read_text())["flash_map"]["examples"]
    flash = running.sim.flash  # 64 MB
    for ex in examples:
        r = _mesp(running, "ComputeHash", {"hashType": ex["hash_type"],
                                           "datasetType": ex["dataset_type"],
                                           "start": ex["start"], "size": ex["size"]})
        if "64" in ex["applies_to"]:
            assert isinstance(r, MespReply), r
            assert r.value.result == flash.hash(ex["hash_type"], ex["start"], ex["size"])
        else:
            assert isinstance(r, MespFailure) and r.ret == 3  # the 128 MB range on a 64 MB flash
    r = _mesp(running, "ComputeHash", {"hashType": 0, "datasetType": 0, "start": 0x1000,
                                       "size": 4096})
    import hashlib
    assert r.value.result == hashlib.sha256(flash.read(0x1000, 4096)).digest()


def test_edr_trigger_is_recorded_and_ffs_errors_are_typed(running) -> None:  # type: ignore[no-untyped-def]
    from eyeq_spi.mesp.replies import MespFailure, MespReply

    r = _mesp(running, "SendParamsToCalibrationTool", {
        "edr_type": 6, "edr_policy": 1, "edr_function": 4, "edr_params_num": 1,
        "params": b"\x01"})
    assert isinstance(r, MespReply) and r.value.edr_function == 4
    assert running.sim.counters.edr_triggers[-1]["params"] == b"\x01"
    r = _mesp(running, "FFSReadFile", {"filename": "/mesp/nope"})
    assert isinstance(r, MespFailure) and r.ret == 5 and r.ret_name == "FILE_NOT_FOUND"
    r = _mesp(running, "SwitchEyeQApplication", {"applicationId": 9})
    assert isinstance(r, MespFailure) and r.ret == 3


def test_fatal_22_that_never_clears_ends_in_failed_not_a_loop() -> None:
    emu = build(sim_config=SimConfig(fatal_error=22))  # the EyeQ reports 22 whatever it gets
    emu.run_for(10.0)
    assert emu.host.state is S.FAILED
    assert "still mismatched" in (emu.host.problem or "")
    assert emu.sim.counters.boots == 4  # the first boot and three resets


@pytest.mark.realtime
def test_real_time_pacing_takes_the_wall_time_of_quiet_stretches_too() -> None:
    """``run_for(S, realtime=True)`` lasts at least S of wall time, including the stretches in
    which nothing is due (a real-time demo of 5 s used to end after 4.5 s). Bounded: a loaded
    machine can only make it longer."""
    import time

    emu = build()
    t0 = time.perf_counter()
    emu.run_for(0.6, realtime=True)
    assert time.perf_counter() - t0 >= 0.58
    assert emu.runner.now == pytest.approx(0.6)


def test_warm_up_builds_every_mesp_encoder_before_real_time() -> None:
    """A MESP encoder built on first use costs milliseconds: in a live run the first request
    then waited past the peer's 10 ms ackTimeout. Both sides build them all in warm_up."""
    emu = build()
    emu.sim.warm_up()
    emu.host.warm_up()
    n = 2 * len(emu.sim.server.codec.functions)
    for codec in (emu.sim.server.codec, emu.sim.codec.mesp, emu.host.mesp.codec,
                  emu.host.codec.mesp):
        assert len(codec._built) == n
