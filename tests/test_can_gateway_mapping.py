"""Decision C4 as data: every CAN signal is either mapped from EyeQ4 DASP data or listed as
unmapped with its reason and sent as its invalid value (or physical 0 when the seed prints
none); the angle convention (mapping.yaml `to_right`) makes a decoded Obstacle_Angle carry the
sign of Obstacle_Pos_Y, right positive as seeds 000 (line 530) and 001 (line 2928) say."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import pytest

can = pytest.importorskip("can", reason="needs the [can] extra (python-can)")
pytest.importorskip("cantools", reason="needs the [can] extra (cantools)")

from eyeq_spi.can.decode import CanDecoder  # noqa: E402
from eyeq_spi.can.gateway import CanGateway, physical_to_raw  # noqa: E402
from eyeq_spi.catalog.can import can_specs, protocol, validate_can_docs  # noqa: E402
from eyeq_spi.catalog.can_expr import MISSING  # noqa: E402


@dataclass
class Dasp:
    name: str
    fields: dict[str, Any]
    errors: list[str] = field(default_factory=list)


def test_every_signal_is_mapped_or_unmapped_with_a_reason() -> None:
    protocols, mapping = can_specs()
    total = unmapped = 0
    for pname, proto in protocols.items():
        pm = mapping.protocols[pname]
        for m in proto.messages:
            mm = pm[m.name]  # every message is in the mapping
            for s in m.signals:
                mapped, listed = s.name in mm.signals, s.name in mm.unmapped
                assert mapped != listed, f"{pname}.{m.name}.{s.name}"
                reason = mm.signals[s.name].reason if mapped else mm.unmapped[s.name]
                assert len(reason.strip()) > (10 if listed else 2), f"{pname}.{m.name}.{s.name}"
                total += 1
                unmapped += listed
    assert total > 150 and 30 <= unmapped < total // 3


def test_validator_requires_the_whole_protocol_to_be_covered() -> None:
    proto = {"name": "x", "messages": [
        {"name": "M", "id": 0x700, "dlc": 1, "cycle_ms": 10, "seed_line": 1, "signals": [
            {"name": "A", "start": 0, "length": 4, "seed_line": 1},
            {"name": "B", "start": 4, "length": 4, "seed_line": 1}]},
        {"name": "N", "id": 0x701, "dlc": 1, "cycle_ms": 10, "seed_line": 1, "signals": [
            {"name": "C", "start": 0, "length": 8, "seed_line": 1}]}]}
    mapping = {"protocols": {"x": {"M": {
        "signals": {"A": {"expr": "1", "reason": "r"}},
        "unmapped": {"A": "twice", "Q": "no such", "B": " "}}}}}
    problems = "\n".join(validate_can_docs({"p.yaml": {"can_protocol": proto},
                                            "m.yaml": {"can_mapping": mapping}}))
    for needle in ("x.N: not mapped", "M.A: both mapped and unmapped",
                   "M.Q: no such signal (unmapped)", "M.B: an unmapped signal says why"):
        assert needle in problems, (needle, problems)
    mapping["protocols"]["x"]["M"] = {"signals": {"A": {"expr": "1", "reason": "r"}},
                                      "extra": {}}
    problems = "\n".join(validate_can_docs({"p.yaml": {"can_protocol": proto},
                                            "m.yaml": {"can_mapping": mapping}}))
    assert "only signals, slots and unmapped" in problems
    mapping["protocols"]["x"]["M"] = {"signals": {"A": {"expr": "1", "reason": "r"}}}
    problems = "\n".join(validate_can_docs({"p.yaml": {"can_protocol": proto},
                                            "m.yaml": {"can_mapping": mapping}}))
    assert "M.B: neither mapped nor listed under unmapped" in problems


OBJECT = {  # one car 20 m ahead, 3 m to the LEFT (latDistance > 0; angleMid < 0, §13.2.5.4)
    "id": 7, "classification": 0, "isCipv": 2, "age": 5, "laneAssignment": 1,
    "isVeryClose": 0,
    "physicalState": {"longDistance": 20.0, "latDistance": 3.0, "absoluteLongVelocity": 20.0,
                      "absoluteLongAcc": 0.0, "length": 4.5, "width": 1.8},
    "angularState": {"angleMid": -math.atan2(3.0, 20.0), "angularSpeed": -0.02},
    "mobilityState": {"motionStatus": 1, "motionOrientation": 0},
    "lightIndicators": {"valid": 0, "turnLeft": 0, "turnRight": 0, "brake": 0},
}


def run_one_cycle(proto: str, fields: dict[str, Dasp]) -> tuple[CanGateway, list[Any]]:
    gw = CanGateway(proto, vehicle=lambda now: {"vehicleVelocity": 25.0})
    for msg in fields.values():
        gw.on_message(msg)
    gw.handle_timer(0.0)
    dec = CanDecoder(proto)
    recs = [dec.decode(can.Message(arbitration_id=f.arbitration_id, data=f.data,
                                   is_extended_id=False), i)
            for i, f in enumerate(gw.frames())]
    return gw, recs


def test_object_angle_is_right_positive_and_lateral_position_left_positive() -> None:
    """C5: on a production camera Obstacle_Pos_Y is left positive (latDistance as it is) while
    Obstacle_Angle is right positive: the two have opposite signs."""
    objs = Dasp("EYEQ_VIS_OBSTACLES_MSG",
                {"timestamp_ms": 0, "visObjects": {"visObs": [OBJECT]}})
    _, recs = run_one_cycle("extlog2", {"o": objs})
    by_name = {r["name"]: r["fields"] for r in recs}
    pos_y = by_name["Obstacle_Data_A_0"]["Obstacle_Pos_Y"]
    angle = by_name["Obstacle_Data_C_0"]["Obstacle_Angle"]
    rate = by_name["Obstacle_Data_C_0"]["Obstacle_Angle_Rate"]
    assert pos_y == pytest.approx(3.0, abs=0.0625)  # left of the car: positive (C5)
    assert angle == pytest.approx(-math.degrees(math.atan2(3.0, 20.0)), abs=0.01)
    assert angle < 0 and rate == pytest.approx(-math.degrees(0.02), abs=0.01)
    _, mapping = can_specs()
    assert dict(mapping.derived)["to_right"].expr == "1"  # seed 004 and the CAN seeds agree
    # the two lateral signs are named parameters of the mapping, with their evidence (C5)
    signs = dict(mapping.derived)
    assert signs["obstacle_y_sign"].expr == "1" and "production" in signs["obstacle_y_sign"].reason
    assert signs["lane_y_sign"].expr == "-1" and "C0" in signs["lane_y_sign"].reason


@pytest.mark.parametrize("proto", ["extlog2", "me8"])
def test_unmapped_signals_send_their_invalid_or_default_value(proto: str) -> None:
    objs = Dasp("EYEQ_VIS_OBSTACLES_MSG",
                {"timestamp_ms": 0, "visObjects": {"visObs": [OBJECT]}})
    gw, recs = run_one_cycle(proto, {"o": objs})
    _, mapping = can_specs()
    pm = mapping.protocols[proto]
    dec = CanDecoder(proto)
    seen = 0
    for r in recs:
        spec = dec.spec_for(r["header"]["id"])
        assert spec is not None
        for name in pm[spec.name].unmapped:
            s = spec.signal(name)
            raw = physical_to_raw(s, MISSING)
            want = s.raw_invalid if s.raw_invalid is not None else raw
            if s.reported_invalid is not None:
                assert name in r["invalid"], (spec.name, name)
            elif s.invalid is not None:  # C8: its invalid value is also a normal state
                assert name not in r["invalid"], (spec.name, name)
            else:  # physical 0, clamped into the printed range
                lo = s.min if s.min is not None else -math.inf
                hi = s.max if s.max is not None else math.inf
                assert raw == round((min(max(0.0, lo), hi) - s.offset) / s.scale)
            got = r["fields"][name]
            assert got == pytest.approx(want * s.scale + s.offset, abs=1e-9), (spec.name, name)
            assert name not in gw.counters.missing  # by design, not "uncomputable"
            seen += 1
    assert seen >= (20 if proto == "extlog2" else 10)
    if proto == "extlog2":
        radar = protocol("extlog2").message("Obstacle_Data_B")
        b0 = next(r for r in recs if r["name"] == "Obstacle_Data_B_0")
        assert {"Radar_Pos_X", "Radar_Vel_X", "Matched_Radar_ID"} <= set(b0["invalid"])
        assert radar.signal("Radar_Pos_X").invalid == 0xFFF


def test_sign_position_and_glare_boundaries_follow_the_angle_convention() -> None:
    sign = {"signType": 4, "signSupplementalType1": 0, "signLongPosition": 30.0,
            "signLatPosition": -4.0, "signHeight": 1.0, "signFilterType": 0,
            "signRelevantDecision": 0}  # 4 m to the LEFT (§16: a negative value is left)
    signs = Dasp("EYEQ_VIS_TRAFFIC_SIGNS_MSG",
                 {"tsrInfo": {"numberTrafficSigns": 1, "trafficSigns": [sign]}})
    spot = {"classification": 1, "leftAngle": -0.10, "rightAngle": -0.05, "bottomAngle": 0.02,
            "topAngle": 0.03, "longPos": 80.0}  # a headlamp pair left of the axis (§15: right +)
    # a nearer pair lower in the image (SW4.0+: above the horizon positive, 004 line 3295)
    near = {**spot, "leftAngle": -0.07, "bottomAngle": -0.03, "topAngle": -0.01, "longPos": 40.0}
    light = Dasp("EYEQ_VIS_LIGHT_SENSOR_DATA_MSG", {"activeLightSensorInfo": {
        "numOfActiveLightSpots": 2, "activeLightSpots": [spot, near], "ahbcAvailable": 1,
        "beamRequest": 0, "villageDetected": 0, "fogDetected": 0, "highwayDetected": 0}})
    _, recs = run_one_cycle("extlog2", {"s": signs, "l": light})
    by_name = {r["name"]: r for r in recs}
    assert by_name["TSR_0"]["fields"]["Sign_Position_Y"] == -4.0  # right positive: left < 0
    g = by_name["AHBC_Gradual"]["fields"]
    # 0x729 counts counter-clockwise (left positive, 001 line 1640): a spot on the left > 0
    assert g["Boundary_Domain_Non_Glare_Left_Hand_HLB"] == pytest.approx(
        math.degrees(0.10), abs=0.1)
    assert g["Boundary_Domain_Non_Glare_Right_Hand_HLB"] == pytest.approx(
        math.degrees(0.05), abs=0.1)
    # the lower boundary is the closest object's, the lowest bottom edge, upwards positive
    # (001 lines 1620, 1676): -0.03 rad, not the farther spot's +0.02
    assert dict(can_specs()[1].derived)["up"].expr == "1"
    assert g["Boundary_Domain_Bottom_Non_Glare_HLB"] == pytest.approx(
        math.degrees(-0.03), abs=0.1)
    assert g["Object_Distance_HLB"] == 40.0


def test_a_valid_value_never_sends_the_invalid_raw_value() -> None:
    gw_sig = protocol("extlog2").message("AHBC_Gradual").signal(
        "Boundary_Domain_Non_Glare_Left_Hand_HLB")
    assert gw_sig.invalid == 0xFF  # 0xFF * 0.1 - 20 = 5.5 deg: inside -20..20 (001 line 1646)
    for deg, want in ((5.5, 256), (5.52, 256), (5.46, 254), (5.45, 254), (5.6, 256)):
        raw = physical_to_raw(gw_sig, deg)
        assert raw == want and abs(raw * 0.1 - 20 - deg) <= 0.1 + 1e-9, (deg, raw)
    assert physical_to_raw(gw_sig, MISSING) == 0xFF and physical_to_raw(gw_sig, 30.0) == 0xFF
    failsafe = protocol("extlog2").message("Obstacle_Status").signal("Failsafe")
    assert physical_to_raw(failsafe, 0) == 0  # bit fields keep their printed "invalid" 0
