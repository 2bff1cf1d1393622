"""DASP payloads packed in place (eyeq_spi/sim/dasp_fast.py) against the reference (a value
dict filled by ``Scene.fill`` and packed by ``MessageCodec.encode_dasp``): identical bytes,
message by message through the public API of both, and transfer by transfer on the wire."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eyeq_spi.catalog.messages import MessageDef, catalog
from eyeq_spi.catalog.schema import sw_key
from eyeq_spi.codec.e2e import E2EState, compile_protector, protect
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.emulator import build
from eyeq_spi.errors import LocalProtocolError
from eyeq_spi.host.host import HostConfig
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.host.scenario import CsvScenario
from eyeq_spi.sim.calibration import fill_calibration
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.sim.dasp_fast import DaspPacker
from eyeq_spi.sim.scene import Scene, SceneConfig

pytestmark = pytest.mark.twin  # runs a reference/fast twin: also run with EYEQ_SPI_EXACT=1

SWS = catalog().sw_versions
CALIBRATED = ("EYEQ_TAC_CAL_MSG", "EYEQ_DYNAMIC_CAL_MSG")


def dasp_messages(codec: MessageCodec) -> list[MessageDef]:
    """Every DASP message an EyeQ of the codec's release sends, in every mode."""
    return [m for m in codec.cat.messages
            if m.protocol == "DASP" and m.direction == "e2h" and m.exists_in(codec.sw)]


class Twins:
    """One scene, written twice: into the reference's value dicts and into packers."""

    def __init__(self, sw: str | None, **scene: Any) -> None:
        self.codec = MessageCodec(sw)
        config = SceneConfig(**scene, spot_angles_up=sw_key(self.codec.sw) >= sw_key("sw4"))
        self.scenes = (Scene(config), Scene(config))
        self.messages = dasp_messages(self.codec)
        self.values = {m.name: self.codec.layout(m).zero_values() for m in self.messages}
        self.packers = {m.name: DaspPacker(self.codec.layout(m), m.data_id)
                        for m in self.messages}
        self.e2e = (E2EState(), E2EState())

    def step(self, time_s: float, speed: float | None = None, yaw: float | None = None) -> None:
        for scene in self.scenes:
            scene.step(time_s, speed, yaw)

    def messages_at(self, time_s: float, counter: int,
                    calibrating_from: float | None = None) -> tuple[list[bytes], list[bytes]]:
        """Every message of the release at ``time_s``, by the reference and packed."""
        ref: list[bytes] = []
        packed: list[bytes] = []
        for msg in self.messages:
            packer = self.packers[msg.name]
            for values, scene in ((self.values[msg.name], self.scenes[0]),
                                  (packer.root, self.scenes[1])):
                if calibrating_from is not None and msg.name in CALIBRATED:
                    fill_calibration(msg.name, values, time_s,  # type: ignore[arg-type]
                                     calibrating_from, 0.5, 3, None)
                else:
                    scene.fill(msg.name, values, time_s)  # type: ignore[arg-type]
            ref.append(self.codec.encode_dasp(msg.name, self.values[msg.name], counter,
                                              self.e2e[0]))
            packed.append(packer.encode(counter, self.e2e[1]))
        return ref, packed

    def compare(self, times: list[float], ego: tuple[float | None, float | None] = (None, None),
                calibrating_from: float | None = None) -> int:
        """Step to each time and compare every message; returns the messages compared."""
        compared = 0
        for index, time_s in enumerate(times):
            self.step(time_s, *ego)
            ref, packed = self.messages_at(time_s, index & 0xFF, calibrating_from)
            for msg, a, b in zip(self.messages, ref, packed, strict=True):
                assert a == b, (self.codec.sw, msg.name, time_s,
                                [i for i in range(len(a)) if a[i] != b[i]][:8])
            compared += len(ref)
        return compared


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), sw=st.sampled_from(SWS),
       objects=st.sampled_from([0, 1, 7, 15]), signs=st.sampled_from([0, 3, 20]),
       spots=st.sampled_from([0, 2, 15]),
       steps=st.lists(st.floats(0.0, 0.5), min_size=1, max_size=5),
       speed=st.one_of(st.none(), st.floats(-20.0, 100.0)),
       yaw=st.one_of(st.none(), st.floats(-0.5, 0.5)))
def test_packed_bytes_equal_the_reference(seed: int, sw: str, objects: int, signs: int,
                                          spots: int, steps: list[float], speed: float | None,
                                          yaw: float | None) -> None:
    twins = Twins(sw, seed=seed, objects=objects, signs=signs, light_spots=spots)
    times, time_s = [], 0.0
    for delta in steps:
        time_s += delta
        times.append(time_s)
    assert twins.compare(times, (speed, yaw)) > 0


@pytest.mark.parametrize("sw", [SWS[0], "sw5", SWS[-1]])
def test_full_load_over_many_frames_and_calibration(sw: str) -> None:
    Twins(sw, seed=11, objects=15, signs=20, light_spots=15).compare(
        [k / 18 for k in range(40)])
    # TAC/SPC results in progress, then done (fill_calibration reads a member back)
    Twins(sw, seed=3, objects=15, signs=20, light_spots=15).compare(
        [2.0 + k / 18 for k in range(20)], calibrating_from=2.0)


@pytest.mark.parametrize("sw", ["sw4", SWS[-1]])
def test_slots_emptied_between_frames_are_cleared_as_the_reference_clears_them(sw: str) -> None:
    """Objects, signs and light spots that vanish leave slots the next frame must zero (stale
    values, bitfields included, would differ): kill some in both scenes between frames."""
    twins = Twins(sw, seed=5, objects=15, signs=20, light_spots=15)
    twins.compare([0.5, 1.0])
    for kill in (slice(0, None, 2), slice(None)):
        for scene in twins.scenes:
            scene.world.alive[kill] = False
            scene.world.sg_alive[kill] = False
            scene._cols = None  # the obstacle columns again, from the world as it now is
        ref, packed = twins.messages_at(1.0, 0)
        assert ref == packed


@pytest.mark.parametrize("sw", SWS)
def test_every_message_of_every_release_at_full_load(sw: str) -> None:
    twins = Twins(sw, seed=23, objects=15, signs=20, light_spots=15)
    assert twins.compare([0.4 + k / 18 for k in range(6)], (27.0, 0.01)) \
        == 6 * len(twins.messages)


@pytest.mark.parametrize("sw", [SWS[0], "sw5", SWS[-1]])
def test_a_long_run_wraps_every_counter_alike(sw: str) -> None:
    """300 frames: the DASP header counters and the E2E rolling counters (D5; none before the
    releases with CRCs) wrap, on both paths alike, byte for byte."""
    twins = Twins(sw, seed=29, objects=15, signs=20, light_spots=15)
    twins.compare([k / 18 for k in range(300)])
    assert twins.e2e[0].sent == twins.e2e[1].sent
    assert all(v < 64 for v in twins.e2e[1].sent.values())  # 300 sent: wrapped past 255
    assert bool(twins.e2e[1].sent) or sw == SWS[0]


def test_the_protector_is_protect() -> None:
    codec = MessageCodec("sw9")
    for m in dasp_messages(codec):
        lay = codec.layout(m)
        data = bytearray(lay.build(lay.zero_values()))
        data[::7] = bytes(len(data[::7]))
        ref, new = bytearray(data), bytearray(data)
        s1, s2 = E2EState(), E2EState()
        for _ in range(3):
            protect(ref, lay, s1)
            compile_protector(lay)(new, s2)
            assert ref == new and s1.sent == s2.sent


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


def test_the_streams_are_sent_alike_and_staggered(tmp_path: Path) -> None:
    """In Running Vision every DASP stream of the mode is sent at the same rate (within one
    message), the first of each at a different instant (staggered over one period)."""
    emu = build(nvm=Nvm(tmp_path / "nvm.json"))
    emu.run_for(2.0)  # the first power-up writes the NVM (fatal 22, reset)
    emu = build(nvm=Nvm(tmp_path / "nvm.json"))
    emu.run_for(4.0)
    names = [m.name for m in dasp_messages(emu.host.codec) if "APP" in m.modes]
    times = emu.host.counters.rx_times
    counts = [len(times[name]) for name in names]
    assert min(counts) > 18 and max(counts) - min(counts) <= 1
    firsts = [times[name][0] for name in names]
    assert len(set(firsts)) == len(firsts) and max(firsts) - min(firsts) < 1 / 18
