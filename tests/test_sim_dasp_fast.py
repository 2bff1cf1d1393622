"""DASP payloads packed in place (eyeq_spi/sim/dasp_fast.py) against the reference
(Scene.fill + MessageCodec.encode_dasp): identical bytes, message by message and
transfer by transfer; and the due heap of SimulatedEyeQ._send_due_dasp."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eyeq_spi.catalog.messages import MessageDef, catalog
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.emulator import build
from eyeq_spi.errors import LocalProtocolError
from eyeq_spi.host.host import HostConfig
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.host.scenario import CsvScenario
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.sim.dasp_fast import DaspPacker
from eyeq_spi.sim.eyeq import Phase, SimulatedEyeQ

pytestmark = pytest.mark.twin  # runs a reference/fast twin: also run with EYEQ_SPI_EXACT=1

SWS = catalog().sw_versions


def _dasp(sim: SimulatedEyeQ) -> list[MessageDef]:
    return [m for m in sim.codec.cat.messages
            if m.protocol == "DASP" and m.direction == "e2h" and m.exists_in(sim.sw)]


def _pair(**kw: Any) -> tuple[SimulatedEyeQ, SimulatedEyeQ]:
    ref = SimulatedEyeQ(SimConfig(dasp_packer=False, **kw))
    new = SimulatedEyeQ(SimConfig(dasp_packer=True, **kw))
    for sim in (ref, new):
        sim.warm_up()
    return ref, new


def _compare(ref: SimulatedEyeQ, new: SimulatedEyeQ, times: list[float],
             ego: tuple[float | None, float | None] = (None, None),
             calibrating_from: float | None = None) -> int:
    """Step both scenes to each time and encode every DASP message of the release (every mode's)
    with both paths: the bytes must be identical. Returns the messages compared."""
    msgs = _dasp(ref)
    n = 0
    for k, t in enumerate(times):
        for sim in (ref, new):
            sim.scene.step(t, *ego)
            sim._cal_started = calibrating_from if calibrating_from is not None \
                and t >= calibrating_from else None
        for m in msgs:
            a = ref._dasp_bytes(m, k & 0xFF, t)
            b = new._dasp_bytes(m, k & 0xFF, t)
            assert a == b, (ref.sw, m.name, t, [i for i in range(len(a)) if a[i] != b[i]][:8])
            n += 1
    assert ref.dasp_paths["packed"] == 0 and new.dasp_paths["dict"] == 0
    assert new.dasp_paths["packed"] == n
    return n


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), sw=st.sampled_from(SWS),
       objects=st.sampled_from([0, 1, 7, 15]), signs=st.sampled_from([0, 3, 20]),
       spots=st.sampled_from([0, 2, 15]),
       steps=st.lists(st.floats(0.0, 0.5), min_size=1, max_size=5),
       speed=st.one_of(st.none(), st.floats(-20.0, 100.0)),
       yaw=st.one_of(st.none(), st.floats(-0.5, 0.5)))
def test_packer_bytes_equal_the_dict_path(seed: int, sw: str, objects: int, signs: int,
                                          spots: int, steps: list[float], speed: float | None,
                                          yaw: float | None) -> None:
    ref, new = _pair(sw=sw, seed=seed, objects=objects, signs=signs, light_spots=spots)
    times, t = [], 0.0
    for dt in steps:
        t += dt
        times.append(t)
    assert _compare(ref, new, times, (speed, yaw)) > 0


@pytest.mark.parametrize("sw", [SWS[0], "sw5", SWS[-1]])
def test_full_load_over_many_frames_and_calibration(sw: str) -> None:
    ref, new = _pair(sw=sw, seed=11, objects=15, signs=20, light_spots=15)
    _compare(ref, new, [k / 18 for k in range(40)])
    # TAC/SPC results in progress, then done (sim.calibration.fill_calibration reads a member back)
    ref2, new2 = _pair(sw=sw, seed=3, objects=15, signs=20, light_spots=15, tac_duration=0.5)
    _compare(ref2, new2, [2.0 + k / 18 for k in range(20)], calibrating_from=2.0)


@pytest.mark.parametrize("sw", ["sw4", SWS[-1]])
def test_slots_emptied_between_frames_are_cleared_as_the_dict_path_clears_them(sw: str) -> None:
    """Objects, signs and light spots that vanish leave slots the next frame must zero (stale
    values, bitfields included, would differ): kill some in both scenes between frames."""
    ref, new = _pair(sw=sw, seed=5, objects=15, signs=20, light_spots=15)
    _compare(ref, new, [0.5, 1.0])
    for kill in (slice(0, None, 2), slice(None)):
        for sim in (ref, new):
            sim.scene._alive[kill] = False
            sim.scene._sg_alive[kill] = False
            sim.scene._cols = None
            sim.scene._after_step()
        msgs = _dasp(ref)
        for m in msgs:
            assert ref._dasp_bytes(m, 0, 1.0) == new._dasp_bytes(m, 0, 1.0), m.name


def test_views_refuse_what_the_encoder_refuses() -> None:
    codec = MessageCodec("sw9")
    m = codec.cat.message("EYEQ_VIS_FAILSAFE_MSG")
    p = DaspPacker(codec.layout(m), m.data_id)
    fs = p.root["visFailsafes"]
    with pytest.raises(LocalProtocolError):
        fs["outOfCalibTSR"] = 64  # a 6-bit member
    with pytest.raises(LocalProtocolError):
        fs["freeSight"] = 1.5  # a float in an integer member
    with pytest.raises(LocalProtocolError):
        p.encode(256, None)
    fs["outOfCalibTSR"] = 1
    assert fs["outOfCalibTSR"] == 1 and "freeSight" in fs and "nope" not in fs


def _trace(tmp_path: Path, packer: bool, *, host: HostConfig | None = None,
           scenario: Path | None = None, seconds: float = 3.0, **sim: Any) -> list[str]:
    out: list[str] = []
    nvm = Nvm(tmp_path / f"nvm-{packer}.json")
    build(nvm=nvm).run_for(2.0)  # the first power-up writes the NVM (fatal 22, reset)
    emu = build(sim_config=SimConfig(dasp_packer=packer, **sim), host_config=host, nvm=nvm,
                scenario=CsvScenario(scenario) if scenario else None,
                tap=lambda node, t, data: out.append(f"{node} {t:.9f} "
                                                     + hashlib.sha256(data).hexdigest()))
    emu.run_for(seconds)
    assert emu.sim.dasp_paths["dict" if not packer else "packed"] > 0
    assert emu.sim.dasp_paths["packed" if not packer else "dict"] == 0
    return out


@pytest.mark.parametrize("case", ["full", "aeb", "csv", "stop"])
def test_wire_trace_is_identical(tmp_path: Path, case: str) -> None:
    kw: dict[str, Any] = {"objects": 15, "signs": 20, "light_spots": 15}
    if case == "aeb":
        kw = {"host": HostConfig(camera_only_aeb=True), "objects": 0, "signs": 0,
              "light_spots": 0}
    elif case == "csv":
        csv = tmp_path / "drive.csv"
        csv.write_text("time,vehicleVelocity,vehicleYawRate\n0,10,0\n1,25,0.05\n2,5,-0.1\n")
        kw = {"scenario": csv, "seed": 7}
    elif case == "stop":
        kw = {"stop_dasp": {"EYEQ_VIS_OBSTACLES_MSG": 1.0, "EYEQ_VIS_SRP_MSG": 0.5}}
    ref, new = _trace(tmp_path, False, **kw), _trace(tmp_path, True, **kw)
    assert len(ref) > 500
    assert ref == new


def test_due_heap_sends_as_the_scan_did() -> None:
    """The heap sends the due messages in catalogue order and get_timer stays exact: the next
    due time is the earliest of them, and a cleared schedule is staggered afresh."""
    sim = SimulatedEyeQ(SimConfig())
    sim.phase, sim.main_state = Phase.RUNNING, 0x02  # Running Vision
    sent: list[str] = []
    sim._send = lambda message, now: sent.append(  # type: ignore[method-assign]
        sim.codec.decode(message).name or "")
    sim._send_due_dasp(0.0)
    msgs = [m.name for m in _dasp(sim) if "APP" in m.modes]
    assert sent == msgs[:1]
    assert sim._dasp_min == min(sim._next_dasp.values())
    t = 0.0
    for _ in range(200):
        t = sim._dasp_min
        sim._send_due_dasp(t)
        assert sim._dasp_min == min(sim._next_dasp.values()) > t
    assert sorted(set(sent)) == sorted(msgs)
    assert max(sent.count(n) for n in msgs) - min(sent.count(n) for n in msgs) <= 1
    sim._next_dasp.clear()  # e.g. a mode change: the schedule starts over
    sent.clear()
    sim._send_due_dasp(t + 0.01)
    assert sent == msgs[:1] and len(sim._next_dasp) == len(msgs)


@pytest.mark.parametrize("sw", SWS)
def test_every_message_of_every_release_at_full_load(sw: str) -> None:
    """Every DASP message the simulated EyeQ sends at every release, packed and by the dict
    path, over a few frames of a full scene (objects, signs and light spots at their maxima)."""
    ref, new = _pair(sw=sw, seed=23, objects=15, signs=20, light_spots=15)
    assert _compare(ref, new, [0.4 + k / 18 for k in range(6)], (27.0, 0.01)) \
        == 6 * len(_dasp(ref))


def _stream(sim: SimulatedEyeQ, seconds: float) -> list[tuple[float, bytes]]:
    """What ``_send_due_dasp`` sends in Running Vision over ``seconds`` (the link stubbed)."""
    out: list[tuple[float, bytes]] = []
    sim.phase, sim.main_state = Phase.RUNNING, 0x02  # Running Vision
    sim._send = lambda message, now: out.append((now, message))  # type: ignore[method-assign]
    sim._send_due_dasp(0.0)
    while sim._dasp_min < seconds:
        sim._send_due_dasp(sim._dasp_min)
    return out


@pytest.mark.parametrize("sw", [SWS[0], "sw5", SWS[-1]])
def test_a_long_run_wraps_every_counter_alike(sw: str) -> None:
    """Over 16 simulated seconds each message is sent more than 256 times: the DASP header
    counters and the E2E rolling counters (D5; none before the releases with CRCs) wrap, on
    both paths alike, byte for byte."""
    ref, new = _pair(sw=sw, seed=29, objects=15, signs=20, light_spots=15)
    a, b = _stream(ref, 16.0), _stream(new, 16.0)
    assert len(a) == len(b) > 256 * 10
    for k, (x, y) in enumerate(zip(a, b, strict=True)):
        assert x == y, (sw, k, x[0])
    assert new.dasp_paths["dict"] == 0 and ref.dasp_paths["packed"] == 0
    assert min(new.counters.sent.values()) > 256
    assert max(new._dasp_counter.values()) < 64  # 289 or 290 sent: wrapped past 255
    assert all(v < 64 for v in new.e2e.sent.values())
    assert new.e2e.sent == ref.e2e.sent and (bool(new.e2e.sent) or sw == SWS[0])
