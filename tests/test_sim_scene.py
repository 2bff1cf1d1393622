"""The seeded driving scene (eyeq_spi.sim.scene): reproducibility, encodability in every release,
ranges, tracking invariants, kinematics, road model, counts and speed."""

from __future__ import annotations

import copy
import math
import statistics
from collections.abc import Iterator
from typing import Any

import pytest

from eyeq_spi.catalog.messages import catalog
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.layout import Layout
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.sim.scene import CLASSES, Scene, SceneConfig

CAT = catalog()
DT = 1.0 / 18.0
OBST = "EYEQ_VIS_OBSTACLES_MSG"
ROAD = "EYEQ_VIS_ROAD_DATA_MSG"
TSR = "EYEQ_VIS_TRAFFIC_SIGNS_MSG"
LIGHTS = "EYEQ_VIS_LIGHT_SENSOR_DATA_MSG"
MESSAGES = (OBST, ROAD, TSR, LIGHTS, "EYEQ_VIS_AEB_INFO_MSG", "EYEQ_VIS_FAILSAFE_MSG",
            "EYEQ_VIS_SRP_MSG", "EYEQ_TIMESYNC_MSG", "EYEQ_SAFETY_MSG", "EYEQ_DYNAMIC_CAL_MSG")
CODECS: dict[str, MessageCodec] = {}


def codec(sw: str = "sw9") -> MessageCodec:
    if sw not in CODECS:
        CODECS[sw] = MessageCodec(sw)
    return CODECS[sw]


def layout(name: str, sw: str = "sw9") -> Layout:
    c = codec(sw)
    return c.layout(c.message(name))


def exists(name: str, sw: str) -> bool:
    return CAT.message(name).exists_in(CAT.sw(sw))


def enum(enum_name: str, value_name: str) -> int:
    return next(v.value for v in CAT.enums[enum_name].values.values() if v.name == value_name)


CIPV = enum("object_is_cipv", "CIPV")
EGO_LANE = enum("object_lane_assignment", "EGO_LANE")


def run(scene: Scene, seconds: float, start: int = 0, **step: Any) -> Iterator[float]:
    """Step ``scene`` at 18 Hz, yielding each time after the step."""
    for k in range(start, start + round(seconds * 18)):
        t = k * DT
        scene.step(t, **step)
        yield t


def filled(scene: Scene, name: str, t: float, sw: str = "sw9") -> dict[str, Any]:
    values = layout(name, sw).zero_values()
    scene.fill(name, values, t)
    return values


def objects(values: dict[str, Any]) -> list[dict[str, Any]]:
    return [o for o in values["visObjects"]["visObs"] if o["id"] != 0]


def leaves(lay: Layout, values: dict[str, Any], path: str = "") -> Iterator[tuple[str, Any, Any]]:
    """(path, value, Member) of every primitive member, array elements one by one."""
    for f in lay.fields:
        child = lay.children.get(f.name)
        v = values[f.name]
        items = list(enumerate(v)) if f.count else [(None, v)]
        for i, x in items:
            p = f"{path}{f.name}" + ("" if i is None else f"[{i}]")
            if child is not None:
                yield from leaves(child, x, p + ".")
            else:
                yield p, x, f.member


# -- reproducibility ----------------------------------------------------------------------------
def trace(seed: int, steps: int = 100) -> list[dict[str, Any]]:
    scene = Scene(SceneConfig(seed=seed, objects=12, signs=6, light_spots=6))
    out = []
    for t in run(scene, steps * DT):
        out.append({name: filled(scene, name, t) for name in MESSAGES})
    return out


def test_same_seed_gives_identical_payloads() -> None:
    a, b = trace(7), trace(7)
    assert len(a) == 100
    assert a == b


def test_different_seed_gives_different_payloads() -> None:
    a, b = trace(7, 20), trace(8, 20)
    assert a[0][OBST] != b[0][OBST]
    assert a[-1][ROAD] != b[-1][ROAD]


def test_fill_reads_state_only() -> None:
    """Filling (more, or less, often) does not change what the world does."""
    busy, quiet = Scene(SceneConfig(seed=3)), Scene(SceneConfig(seed=3))
    for t in run(busy, 3.0):
        for name in MESSAGES:
            filled(busy, name, t)
    for _ in run(quiet, 3.0):
        pass
    t = 3.0
    assert filled(busy, OBST, t) == filled(quiet, OBST, t)


# -- every message encodes in every release, inside its ranges ---------------------------------
def in_range(value: float, member: Any) -> bool:
    tol = 1e-6 * max(1.0, abs(value))  # real32 rounding on the wire
    lo_ok = member.min is None or value >= member.min - tol
    hi_ok = member.max is None or value <= member.max + tol
    return lo_ok and hi_ok


@pytest.mark.parametrize("sw", CAT.sw_versions)
def test_every_filled_message_encodes_and_decodes(sw: str) -> None:
    c = codec(sw)
    scene = Scene(SceneConfig(seed=11, objects=15, signs=20, light_spots=15))
    names = [n for n in MESSAGES if exists(n, sw)]
    assert OBST in names and ROAD in names
    e2e_tx, e2e_rx = E2EState(), E2EState()
    touched: set[str] = set()
    # 18 Hz, then long steps (integrated in pieces)
    times = [k * DT for k in range(20)] + [19 * DT + 0.8 * k for k in range(1, 21)]
    for k, t in enumerate(times):
        scene.step(t)
        for name in names:
            values = filled(scene, name, t, sw)
            lay = layout(name, sw)
            data = c.encode_dasp(name, values, k & 0xFF, e2e_tx)
            dec = c.decode(data, e2e_rx)
            assert dec.ok, (name, dec.errors)
            assert dec.name == name
            for path, value, member in leaves(lay, dec.fields):
                if value:
                    touched.add(f"{name}.{path}")
                # zero is what the scene leaves in members it does not use (invalid slots)
                assert value == 0 or in_range(value, member), (sw, name, path, value, member)
    assert f"{OBST}.visObjects.visObs[14].physicalState.longDistance" in touched
    assert f"{ROAD}.roadInfo.roadMarkerInfo.hostLeftMarker.laneMarker.a0" in touched


@pytest.mark.parametrize("sw", CAT.sw_versions)
def test_every_layout_is_recognised_by_its_shape(sw: str) -> None:
    """fill() is told no SW version: it must find the ranges of exactly this layout."""
    from eyeq_spi.sim.scene_layout import _candidates, _shape

    for name in MESSAGES:
        if exists(name, sw):
            cands = _candidates(name)
            assert cands is not None
            assert _shape(layout(name, sw).zero_values()) in cands[0], name


def test_a_long_pause_is_cheap_and_keeps_the_scene_valid() -> None:
    scene = Scene(SceneConfig(objects=15))
    scene.step(0.0)
    scene.step(3600.0)  # only the last 30 s are simulated (see Scene.step)
    values = filled(scene, OBST, 3600.0)
    assert len(objects(values)) == 15
    assert values["visObjects"]["frameIndex"] == 3600 * 18


def test_filled_values_keep_python_types() -> None:
    """Reals stay floats and integers ints, so a dict looks the same every frame."""
    scene = Scene()
    scene.step(0.0)
    for name in MESSAGES:
        zero = layout(name).zero_values()
        values = filled(scene, name, 0.0)
        flat_zero = [type(v) for _, v, _ in leaves(layout(name), zero)]
        flat = [type(v) for _, v, _ in leaves(layout(name), values)]
        assert flat == flat_zero, name


def test_unknown_messages_are_left_alone() -> None:
    scene = Scene()
    scene.step(0.0)
    host = layout("HOST_VEH_STATE_MSG").zero_values()
    before = copy.deepcopy(host)
    scene.fill("HOST_VEH_STATE_MSG", host, 0.0)
    assert host == before
    other: dict[str, Any] = {"x": 1}
    scene.fill("NO_SUCH_MSG", other, 0.0)
    assert other == {"x": 1}


def test_a_partial_dict_only_gets_members_it_has() -> None:
    scene = Scene()
    scene.step(0.0)
    values: dict[str, Any] = {"timestamp_ms": 0, "roadInfo": {"frameIndex": 0}}
    scene.fill(ROAD, values, 2.5)
    assert values == {"timestamp_ms": 2500, "roadInfo": {"frameIndex": 45}}


# -- tracking ----------------------------------------------------------------------------------
def test_ids_unique_in_range_and_stable() -> None:
    scene = Scene(SceneConfig(seed=5, objects=15))
    born: dict[int, tuple[int, int]] = {}  # id -> (class, birth frame)
    changes = 0
    for t in run(scene, 60.0):
        objs = objects(filled(scene, OBST, t))
        ids = [o["id"] for o in objs]
        assert len(ids) == len(set(ids)) == 15
        assert all(1 <= i <= 15 for i in ids)
        frame = round(t * 18)
        for o in objs:
            birth = frame - o["age"] + 1
            old = born.get(o["id"])
            if old is not None and old[1] != birth:
                changes += 1  # the id was freed and reused by a new object
            elif old is not None:
                assert old[0] == o["classification"], "an object changed class under its id"
            born[o["id"]] = (o["classification"], birth)
    assert changes > 5, "objects should leave and new ones appear in a minute of driving"


def test_exactly_one_cipv_the_closest_in_the_ego_lane() -> None:
    scene = Scene(SceneConfig(seed=9, objects=15))
    frames_with_cipv = 0
    for t in run(scene, 60.0):
        objs = objects(filled(scene, OBST, t))
        ahead = [o for o in objs if o["laneAssignment"] == EGO_LANE
                 and o["physicalState"]["longDistance"] > 0]
        cipv = [o for o in objs if o["isCipv"] == CIPV]
        if ahead:
            frames_with_cipv += 1
            assert len(cipv) == 1
            closest = min(ahead, key=lambda o: o["physicalState"]["longDistance"])
            assert cipv[0]["id"] == closest["id"]
        else:
            assert cipv == []
    assert frames_with_cipv > 0


def test_lane_assignment_follows_lateral_position() -> None:
    """Lanes are 3.6 m wide around the ego lane centre (the road polynomial), left positive."""
    scene = Scene(SceneConfig(seed=4, objects=15))
    lanes = {enum("object_lane_assignment", n): k for n, k in (
        ("LEFT_NEXT_NEXT", 2), ("LEFT_NEXT", 1), ("EGO_LANE", 0), ("RIGHT_NEXT", -1),
        ("RIGHT_NEXT_NEXT", -2))}
    seen, changing = set(), 0
    for t in run(scene, 60.0):
        road = filled(scene, ROAD, t)["roadInfo"]["roadHppFusionInfo"]["laneCenter"]
        for o in objects(filled(scene, OBST, t)):
            ps = o["physicalState"]
            x = ps["longDistance"]
            offset = ps["latDistance"] - (
                road["a0"] + road["a1"] * x + road["a2"] * x * x + road["a3"] * x**3)
            lane = o["laneAssignment"]
            seen.add(lane)
            changing += 1.2 < abs(offset) < 2.4
            if lane in lanes:
                assert abs(offset - 3.6 * lanes[lane]) <= 1.8 + 1e-6, (lane, offset)
            else:
                assert abs(offset) > 2.5 * 3.6 - 1e-6
    assert changing > 0, "some lane changes"
    assert {k for k, v in lanes.items() if v in (-1, 0, 1)} <= seen


def test_ttc_confidence_age_angles() -> None:
    scene = Scene(SceneConfig(seed=2, objects=15))
    ages: dict[int, int] = {}
    for t in run(scene, 10.0):
        for o in objects(filled(scene, OBST, t)):
            ps, ang = o["physicalState"], o["angularState"]
            x, y = ps["longDistance"], ps["latDistance"]
            closing = 25.0 - ps["absoluteLongVelocity"]
            if x > 0 and closing > 0.1:
                assert o["ttc_const_vel"] == pytest.approx(min(x / closing, 7.0), abs=1e-9)
            else:
                assert o["ttc_const_vel"] == 7.0
            assert 0.5 <= o["confidence"] <= 1.0
            if x > 0.5:
                # §13.2.5.4: "The positive side is to the host's right" (latDistance: left)
                assert ang["angleMid"] == pytest.approx(math.atan2(-y, x))
                assert ang["angleRight"] > ang["angleMid"] > ang["angleLeft"]
                box = o["imageBox"]["rect"]
                assert box["xLeftCoord"] <= box["xRightCoord"]
            for key in ("widthStd", "lengthStd", "longDistanceStd", "latDistanceStd",
                        "absoluteLongVelocityStd", "absoluteLongAccStd"):
                assert 0 < ps[key] <= 0.4 + 0.05 * abs(x), key  # small, grows with range
            last = ages.get(o["id"])
            assert last is None or o["age"] in (last + 1, 1) or o["age"] < last
            ages[o["id"]] = o["age"]


def test_dimensions_match_the_class() -> None:
    dims = {enum("object_classification", c[0]): c[2:5] for c in CLASSES}
    scene = Scene(SceneConfig(seed=6, objects=15))
    classes = set()
    for t in run(scene, 60.0, start=0):
        if round(t * 18) % 18:
            continue
        for o in objects(filled(scene, OBST, t)):
            ps, cls = o["physicalState"], o["classification"]
            classes.add(cls)
            w, length, h = dims[cls]
            assert ps["width"] == pytest.approx(w, rel=0.2)
            assert ps["length"] == pytest.approx(length, rel=0.7 if length > 10 else 0.25)
            assert ps["height"] == pytest.approx(h, rel=0.2)
    assert len(classes) >= 3


# -- kinematics ----------------------------------------------------------------------------------
def test_each_step_is_constant_acceleration_relative_to_the_ego() -> None:
    scene = Scene(SceneConfig(seed=1, objects=15, ego_speed=25.0))
    prev: dict[int, dict[str, Any]] = {}
    checked = 0
    for t in run(scene, 20.0):
        now = {o["id"]: o for o in objects(filled(scene, OBST, t))}
        for i, o in now.items():
            p = prev.get(i)
            if p is None or o["age"] != p["age"] + 1:
                continue
            a, b = p["physicalState"], o["physicalState"]
            rel = a["absoluteLongVelocity"] - 25.0
            expect = a["longDistance"] + rel * DT + 0.5 * a["absoluteLongAcc"] * DT**2
            assert b["longDistance"] == pytest.approx(expect, abs=1e-6)
            v_expect = a["absoluteLongVelocity"] + a["absoluteLongAcc"] * DT
            assert b["absoluteLongVelocity"] == pytest.approx(v_expect, abs=1e-6)
            checked += 1
        prev = now
    assert checked > 1000


def test_one_second_of_steps_follows_the_motion_model() -> None:
    scene = Scene(SceneConfig(seed=8, objects=15, ego_speed=22.0))
    times = list(run(scene, 5.0))  # 90 steps, the last at t = 89/18
    start = {o["id"]: o for o in objects(filled(scene, OBST, times[-1]))}
    accs: dict[int, list[float]] = {i: [] for i in start}
    end: dict[int, dict[str, Any]] = {}
    for t in run(scene, 1.0, start=90):
        end = {o["id"]: o for o in objects(filled(scene, OBST, t))}
        for i, o in end.items():
            accs.setdefault(i, []).append(o["physicalState"]["absoluteLongAcc"])
    steady = 0
    for i, o in start.items():
        e = end.get(i)
        if e is None or e["age"] != o["age"] + 18:
            continue
        a = o["physicalState"]["absoluteLongAcc"]
        if max(abs(x - a) for x in accs[i]) > 0.1:
            continue  # the controller changed its mind during the second
        ps = o["physicalState"]
        expect = ps["longDistance"] + (ps["absoluteLongVelocity"] - 22.0) + 0.5 * a
        assert e["physicalState"]["longDistance"] == pytest.approx(expect, abs=0.05)
        steady += 1
    assert steady >= 5


def test_host_ego_speed_drives_the_relative_motion() -> None:
    scene = Scene(SceneConfig(seed=1, objects=6))
    scene.step(0.0, 10.0, 0.0)
    a = {o["id"]: o for o in objects(filled(scene, OBST, 0.0))}
    scene.step(DT, 10.0, 0.0)
    b = {o["id"]: o for o in objects(filled(scene, OBST, DT))}
    for i, o in a.items():
        ps = o["physicalState"]
        expect = (ps["longDistance"] + (ps["absoluteLongVelocity"] - 10.0) * DT
                  + 0.5 * ps["absoluteLongAcc"] * DT**2)
        assert b[i]["physicalState"]["longDistance"] == pytest.approx(expect, abs=1e-6)
    srp = filled(scene, "EYEQ_VIS_SRP_MSG", DT)["visSRP"]
    assert srp["vehicleVelocity"] == 10.0


# -- road ------------------------------------------------------------------------------------------
def test_lane_markers_follow_a_drifting_clothoid() -> None:
    scene = Scene(SceneConfig(seed=12))
    a2, a3 = [], []
    for t in run(scene, 120.0):
        info = filled(scene, ROAD, t)["roadInfo"]["roadMarkerInfo"]
        left, right = info["hostLeftMarker"], info["hostRightMarker"]
        ll, rr = info["nextLeftLeftMarker"], info["nextRightRightMarker"]
        assert left["laneMarker"]["a0"] == pytest.approx(1.8, abs=0.3)
        assert right["laneMarker"]["a0"] == pytest.approx(-1.8, abs=0.3)
        assert ll["laneMarker"]["a0"] == pytest.approx(5.4, abs=0.3)
        assert rr["laneMarker"]["a0"] == pytest.approx(-5.4, abs=0.3)
        for m in (left, right, ll, rr):
            lm = m["laneMarker"]
            assert lm["a1"] == left["laneMarker"]["a1"]
            assert lm["a2"] == left["laneMarker"]["a2"]
            assert lm["a3"] == left["laneMarker"]["a3"]
            assert 0 < lm["startRange"] < lm["endRange"] <= 128
            assert m["laneMarkerConf"]["confidence"] == enum(
                "road_confidence_level", "Detected lanemark")
            assert m["laneMarkerColor"] == enum("lane_marker_color", "White")
        assert left["laneMarkerType"] == enum("lane_marker_type", "DASHED")
        assert ll["laneMarkerType"] == enum("lane_marker_type", "SOLID")
        assert info["nextLeftRightMarker"]["laneMarkerType"] == enum("lane_marker_type", "INVALID")
        a2.append(left["laneMarker"]["a2"])
        a3.append(left["laneMarker"]["a3"])
    assert max(abs(x) for x in a2) < 0.01
    assert statistics.pstdev(a2) > 1e-4, "curvature should drift"
    assert any(x != 0 for x in a3)


def test_host_yaw_rate_sets_the_curvature() -> None:
    scene = Scene(SceneConfig(seed=12))
    times = list(run(scene, 5.0, ego_speed=20.0, yaw_rate=0.04))
    info = filled(scene, ROAD, times[-1])["roadInfo"]["roadMarkerInfo"]
    lm = info["hostLeftMarker"]["laneMarker"]
    # a2 = curvature / 2 = yaw rate / speed / 2 near the ego (the fit spans 100 m)
    assert lm["a2"] == pytest.approx(0.04 / 20.0 / 2, abs=3e-4)


# -- signs, lights, counts ---------------------------------------------------------------------
def test_traffic_signs_come_and_go() -> None:
    scene = Scene(SceneConfig(seed=21, signs=4))
    limits = {v.value for v in CAT.enums["traffic_sign"].values.values()
              if v.family == "SLI_Explicit"}
    last_pos: dict[int, float] = {}
    seen: set[tuple[int, int]] = set()
    frames_with_signs = 0
    for t in run(scene, 120.0):
        tsr = filled(scene, TSR, t)["tsrInfo"]
        n = tsr["numberTrafficSigns"]
        assert 0 <= n <= 4
        frames_with_signs += n > 0
        now: dict[int, float] = {}
        for s in tsr["trafficSigns"][:n]:
            pos = now[s["signID"]] = s["signLongPosition"]
            assert 0 < pos <= 127
            # "height of sign relative to the sensor": the camera 1.3 m up, signs on posts
            # 1.8-2.6 m, electronic ones on a gantry at 5.5 m
            height = s["signHeight"]
            assert 0.5 - 1e-6 <= height <= 1.3 + 1e-6 or abs(height - 4.2) < 1e-6, height
            if s["signID"] in last_pos:
                assert pos < last_pos[s["signID"]]  # approaching
            seen.add((s["signID"], s["signType"]))
        last_pos = now
        for s in tsr["trafficSigns"][n:]:
            assert s["signLongPosition"] == 0 and s["signType"] == 0
    types = [k for _, k in seen]
    assert len(seen) >= 15, "a new sign every few seconds"
    assert sum(k in limits for k in types) > len(types) / 2, "mostly speed limits"
    assert 0.2 < frames_with_signs / (120 * 18) < 0.95


@pytest.mark.parametrize("count", [0, 1, 8, 15])
def test_object_count_honours_the_config(count: int) -> None:
    scene = Scene(SceneConfig(seed=count, objects=count, light_spots=15))
    for t in run(scene, 30.0):
        if round(t * 18) % 9:
            continue
        values = filled(scene, OBST, t)
        assert len(objects(values)) == count
        assert all(o["id"] == 0 for o in values["visObjects"]["visObs"][count:])
        lights = filled(scene, LIGHTS, t)["activeLightSensorInfo"]
        assert lights["numOfActiveLightSpots"] <= count


def test_light_spots() -> None:
    scene = Scene(SceneConfig(seed=13, objects=10, light_spots=4))
    classes = {enum("light_spot_classification", n) for n in (
        "Pair of Tail-lamps", "Pair of Headlamps", "Tail-lamp")}
    for t in run(scene, 10.0):
        info = filled(scene, LIGHTS, t)["activeLightSensorInfo"]
        ids = {o["id"] for o in objects(filled(scene, OBST, t))}
        n = info["numOfActiveLightSpots"]
        assert n == 4
        for spot in info["activeLightSpots"][:n]:
            assert spot["classification"] in classes
            assert spot["vdID"] in ids
            # §15: right of the sensor positive; SW4.0+ above the horizon positive (line 3295)
            assert spot["rightAngle"] >= spot["leftAngle"]
            assert spot["bottomAngle"] <= spot["topAngle"]
            assert spot["pixelTop"] >= spot["pixelBottom"]  # from the image's bottom left
            assert spot["pixelRight"] >= spot["pixelLeft"]
        assert all(s["classification"] == 0 for s in info["activeLightSpots"][n:])


def test_a_reused_dict_loses_stale_objects() -> None:
    values = layout(OBST).zero_values()
    many, few = Scene(SceneConfig(objects=15)), Scene(SceneConfig(objects=2))
    many.step(0.0)
    few.step(0.0)
    many.fill(OBST, values, 0.0)
    assert len(objects(values)) == 15
    few.fill(OBST, values, 0.0)
    assert len(objects(values)) == 2
    assert values == filled(few, OBST, 0.0)


def test_frame_counters_and_timestamps_increase() -> None:
    scene = Scene()
    last = (-1, -1, -1)
    for t in run(scene, 5.0, start=100):
        info = filled(scene, OBST, t)
        vis = info["visObjects"]
        now = (vis["frameIndex"], vis["timestamp_us"], info["timestamp_ms"])
        assert all(a > b for a, b in zip(now, last, strict=True))
        assert vis["imageIndex"] == vis["frameIndex"] & 0xFFFF
        assert vis["timestamp_us"] == round(t * 1e6)
        last = now




@pytest.mark.parametrize(("sw", "up"), [("sw9", True), ("sw4", True), ("sw3", False),
                                        ("sw2_2", False)])
def test_light_spot_vertical_angles_follow_the_release(sw: str, up: bool) -> None:
    """§15: light-spot top/bottom angles count above the horizon positive in the SW4.0+ table
    (seed 004 lines 3294-3295) and below it before (lines 3256-3257, 3273-3274). The lamps are
    below the camera, so their angles are negative from SW4.0; the bottom edge is lower than the
    top edge either way, and the pixel rows (from the image's bottom) do not change."""
    from eyeq_spi.sim.config import SimConfig
    from eyeq_spi.sim.eyeq import SimulatedEyeQ

    assert SimulatedEyeQ(SimConfig(sw=sw)).scene.world.config.spot_angles_up is up
    scene = Scene(SceneConfig(seed=3, objects=10, light_spots=8, spot_angles_up=up))
    for _ in run(scene, 1.0):
        pass
    spots = filled(scene, LIGHTS, 1.0, sw)["activeLightSensorInfo"]["activeLightSpots"]
    lit = [s for s in spots if s["longPos"] > 0]
    assert lit
    for s in lit:
        lower = s["bottomAngle"] < s["topAngle"] if up else s["bottomAngle"] > s["topAngle"]
        assert lower and (s["bottomAngle"] < 0) is up
        assert s["pixelBottom"] < s["pixelTop"]
