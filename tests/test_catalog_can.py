"""specs/can/: schema, generated DBCs against the specs signal by signal, each signal's
conversion against the seed's printed conversion and range, and encode/decode round trips."""

from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

cantools = pytest.importorskip("cantools", reason="needs the [can] extra (cantools)")

from eyeq_spi.can.dbc import database, dbc_text  # noqa: E402
from eyeq_spi.can.decode import CanDecoder  # noqa: E402
from eyeq_spi.can.gateway import physical_to_raw  # noqa: E402
from eyeq_spi.catalog.can import can_documents, can_specs, protocol, validate_can_docs  # noqa: E402
from eyeq_spi.catalog.can_expr import MISSING, compile_expr  # noqa: E402
from eyeq_spi.errors import SpecError  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SEEDS = ROOT.parent / "shared" / "seeds"


def test_can_specs_validate() -> None:
    assert validate_can_docs(can_documents()) == []
    protocols, mapping = can_specs()
    assert set(protocols) == {"extlog2", "me8"}
    assert mapping.protocols["extlog2"] and mapping.protocols["me8"]


def test_validator_catches_broken_entries() -> None:
    proto = {"name": "x", "messages": [{"name": "M", "id": 0x700, "dlc": 2, "cycle_ms": 10,
             "seed_line": 1, "signals": [
                 {"name": "A", "start": 0, "length": 8, "seed_line": 1},
                 {"name": "E", "start": 15, "length": 1, "seed_line": 1, "enum": "nope"},
                 {"name": "B", "start": 4, "length": 8, "seed_line": 1},
                 {"name": "C", "start": 12, "length": 8, "seed_line": 1},
                 {"name": "D", "start": 0, "length": 1, "seed_line": 1, "invalid": 4}]}]}
    mapping = {"protocols": {"x": {"M": {"signals": {
        "A": {"expr": "__import__('os')", "reason": "r"},
        "B": {"expr": "1"}, "Z": {"expr": "1", "reason": "r"}}}}}}
    problems = validate_can_docs({"p.yaml": {"can_protocol": proto},
                                  "m.yaml": {"can_mapping": mapping}})
    text = "\n".join(problems)
    for needle in ("unknown enum 'nope'", "overlaps A", "exceed DLC 2", "fits 1 bits",
                   "unknown function '__import__'", "add reason", "Z: no such signal"):
        assert needle in text, (needle, problems)


def test_expression_language_refuses_everything_else() -> None:
    names = {"o", "veh"}
    for bad in ("o.__class__", "open('x')", "lambda: 1", "[1 for a in o for b in o]",
                "o if", "x"):
        with pytest.raises(SpecError):
            compile_expr(bad, names, set())
    fn = compile_expr("-o.a.b * 2 if o.a.b > 0 else div(1, 0)", names, set())
    assert fn({"o": {"a": {"b": 1.5}}}) == -3.0
    assert fn({"o": {"a": {"b": -1}}}) is MISSING  # division by zero
    assert fn({"o": None}) is MISSING  # message not received yet


@pytest.mark.parametrize("name", ["extlog2", "me8"])
def test_generated_dbc_loads_back_and_matches_the_spec(name: str, tmp_path: Path) -> None:
    path = tmp_path / f"{name}.dbc"
    path.write_text(dbc_text(name))
    db = cantools.database.load_file(str(path))
    proto = protocol(name)
    n = 0
    for m in proto.messages:
        for _, fid, mname in m.instances():
            dm = db.get_message_by_frame_id(fid)
            assert (dm.name, dm.length, dm.cycle_time, dm.is_extended_frame) == \
                (mname, m.dlc, round(m.cycle_ms), False)
            assert {s.name for s in dm.signals} == {s.name for s in m.signals}
            for s in m.signals:
                ds = dm.get_signal_by_name(s.name)
                assert (ds.start, ds.length, ds.byte_order, ds.is_signed, ds.is_float) == \
                    (s.start, s.length, s.byte_order, s.signed, s.is_float), s.name
                assert math.isclose(ds.scale, s.scale, rel_tol=1e-12), s.name
                assert math.isclose(ds.offset, s.offset, rel_tol=1e-12, abs_tol=1e-15), s.name
                assert (ds.minimum, ds.maximum, ds.unit) == (s.min, s.max, s.unit), s.name
                if s.enum:
                    assert {int(k): str(v) for k, v in ds.choices.items()} == \
                        proto.enums[s.enum], s.name
                else:
                    assert not ds.choices
                # cantools' DBC reader drops raw_invalid: the invalid value travels as the
                # signal attribute GenSigInvalidValue (raw, as a decoder sees it)
                seed = s.seed or m.seed or proto.seed  # the seed its line counts in
                assert ds.comment.startswith(f"seed {seed} line {s.seed_line}"), ds.comment
                attr = ds.dbc.attributes.get("GenSigInvalidValue") if ds.dbc else None
                assert (attr.value if attr is not None else None) == s.reported_invalid, s.name
                n += 1
    assert n >= (500 if name == "extlog2" else 60)
    assert db.dbc.attributes["Baudrate"].value == proto.bitrate
    if name == "extlog2":  # 8000h printed, two's complement in a 16-bit signed field
        curv = db.get_message_by_name("Lane").get_signal_by_name("Lane_Curvature")
        assert curv.dbc.attributes["GenSigInvalidValue"].value == -0x8000
    # and the attribute survives cantools' own load -> dump -> load
    again = cantools.database.load_string(db.as_dbc_string())
    invalid = [s.dbc.attributes["GenSigInvalidValue"].value for m in again.messages
               for s in m.signals if s.dbc and "GenSigInvalidValue" in s.dbc.attributes]
    assert sorted(invalid) == sorted(s.reported_invalid for m in proto.messages
                                     for _ in m.instances() for s in m.signals
                                     if s.reported_invalid is not None)


# (protocol, message, signal): (scale, offset) transcribed from the seed's "Conversion" lines
SEED_CONVERSIONS: dict[tuple[str, str, str], tuple[float, float]] = {
    ("extlog2", "Lane", "Lane_Curvature"): (3.81e-6, 0),       # 001 l.1821, 000 l.119
    ("extlog2", "Lane", "Lane_Heading"): (0.0005, 0),          # l.1833
    ("extlog2", "Lane", "Yaw_Angle"): (1 / 1024, -0x7FFF / 1024),  # l.1865 (HEX-0x7FFF)/1024
    ("extlog2", "Lane", "Pitch_Angle"): (1 / 1024 / 512, -0x7FFF / 1024 / 512),  # l.1855
    ("extlog2", "Obstacle_Data_A", "Obstacle_Pos_X"): (0.0625, 0),  # l.2023
    ("extlog2", "Obstacle_Data_A", "Obstacle_Pos_Y"): (0.0625, 0),  # l.2035
    ("extlog2", "Obstacle_Data_A", "Obstacle_Rel_Vel_X"): (0.0625, 0),  # l.2047
    ("extlog2", "Obstacle_Data_B", "Obstacle_Length"): (0.5, 0),  # l.2157
    ("extlog2", "Obstacle_Data_B", "Obstacle_Width"): (0.05, 0),  # l.2167
    ("extlog2", "Obstacle_Data_B", "Radar_Pos_X"): (0.0625, 0),  # l.2213
    ("extlog2", "Obstacle_Data_B", "Radar_Vel_X"): (0.0625, 0),  # l.2225
    ("extlog2", "Obstacle_Data_C", "Obstacle_Angle_Rate"): (0.01, 0),  # l.2285
    ("extlog2", "Obstacle_Data_C", "Obstacle_Scale_Change"): (0.0002, 0),  # l.2299
    ("extlog2", "Obstacle_Data_C", "Object_Accel_X"): (0.03, 0),  # l.2309
    ("extlog2", "Obstacle_Data_C", "Obstacle_Angle"): (0.01, 0),  # l.2325
    ("extlog2", "AWS_Display", "Headway_Measurement"): (0.1, 0),  # l.1277
    ("extlog2", "TSR", "Sign_Position_X"): (0.5, 0),  # l.1496
    ("extlog2", "AHBC_Gradual", "Boundary_Domain_Bottom_Non_Glare_HLB"): (0.1, -10),  # l.1634
    ("extlog2", "AHBC_Gradual", "Boundary_Domain_Non_Glare_Left_Hand_HLB"): (0.1, -20),
    ("extlog2", "AHBC_Gradual", "Object_Distance_HLB"): (2, 0),  # l.1684
    ("extlog2", "Lane_AfterMarket", "Distance_To_Left_Lane"): (0.02, 0),  # l.2355
    ("extlog2", "LKA_Left_Lane_A", "Position_Parameter_C0"): (1 / 256, 0),  # l.2472
    ("extlog2", "LKA_Left_Lane_A", "Curvature_Parameter_C2"): (1 / 1024 / 1000,
                                                               -0x7FFF / 1024 / 1000),
    ("extlog2", "LKA_Left_Lane_A", "Curvature_Derivative_Parameter_C3"): (1 / (1 << 28),
                                                                          -0x7FFF / (1 << 28)),
    ("extlog2", "LKA_Left_Lane_A", "Width_Left_Marking"): (0.01, 0),  # l.2499
    ("extlog2", "LKA_Left_Lane_B", "Heading_Angle_Parameter_C1"): (1 / 1024, -0x7FFF / 1024),
    ("extlog2", "LKA_Left_Lane_B", "View_Range"): (1 / 256, 0),  # l.2529
    ("extlog2", "Reference_Points", "Ref_Point_1_Position"): (1 / 256, -0x7FFF / 256),
    ("me8", "ME8_Gyro", "Yaw_Rate"): (-0.00875, 0),  # 003 l.726
    ("me8", "ME8_Display_Warnings", "Headway_Measurement"): (0.1, 0),  # tenths of seconds
}


@pytest.mark.parametrize(("key", "conv"), sorted(SEED_CONVERSIONS.items()))
def test_conversion_and_range_as_the_seed_prints_them(key: tuple[str, str, str],
                                                      conv: tuple[float, float]) -> None:
    pname, mname, sname = key
    s = protocol(pname).message(mname).signal(sname)
    assert math.isclose(s.scale, conv[0], rel_tol=1e-12)
    assert math.isclose(s.offset, conv[1], rel_tol=1e-12, abs_tol=1e-15)
    lo, hi = s.raw_limits
    # the printed range fits the field (within one raw step at the edges)
    ends = sorted((lo * s.scale + s.offset, hi * s.scale + s.offset))
    if s.min is not None:
        assert ends[0] <= s.min + abs(s.scale)
    if s.max is not None:
        assert ends[1] >= s.max - abs(s.scale)
    if s.raw_invalid is not None:
        assert lo <= s.raw_invalid <= hi


def test_every_signal_range_fits_its_field() -> None:
    for pname in ("extlog2", "me8"):
        for m in protocol(pname).messages:
            for s in m.signals:
                if s.is_float or s.min is None or s.max is None:
                    continue
                lo, hi = s.raw_limits
                ends = sorted((lo * s.scale + s.offset, hi * s.scale + s.offset))
                assert ends[0] <= s.min + abs(s.scale) and ends[1] >= s.max - abs(s.scale), \
                    f"{pname}.{m.name}.{s.name}"


@pytest.mark.skipif(not SEEDS.exists(), reason="the OCR'd seed texts are not beside the clone")
def test_seed_lines_point_at_the_signal_text() -> None:
    """Every message and signal cites a line of its seed near its name (spaces and case aside)."""
    def squash(t: str) -> str:
        return "".join(c for c in t.lower() if c.isalnum())

    for rel, doc in can_documents().items():
        p = doc.get("can_protocol") if isinstance(doc, dict) else None
        if not p:
            continue
        files = {k: (SEEDS / v).read_text(encoding="utf-8").splitlines()
                 for k, v in p["seeds"].items()}
        for m in p["messages"]:
            lines = files[m.get("seed", p["seed"])]
            assert f"{m['id']:x}" in lines[m["seed_line"] - 1].lower(), (rel, m["name"])
            for s in m["signals"]:
                window = squash(" ".join(lines[max(s["seed_line"] - 4, 0):s["seed_line"] + 3]))
                words = [w for w in s.get("seed_form", s["name"]).lower().split("_")
                         if len(w) > 2 and w not in ("display1", "display2", "display3",
                                                     "display4", "byte1", "byte2")] \
                    or [s["name"]]
                assert any(squash(w) in window for w in words), (rel, m["name"], s["name"])


def _frame_values() -> st.SearchStrategy[tuple[str, str, dict[str, Any]]]:
    messages = [(p, m) for p in ("extlog2", "me8") for m in protocol(p).messages]

    @st.composite
    def build(draw: Any) -> tuple[str, str, dict[str, Any]]:
        pname, m = draw(st.sampled_from(messages))
        values: dict[str, Any] = {}
        for s in m.signals:
            if s.is_float:
                values[s.name] = draw(st.floats(-1e6, 1e6, width=32))
                continue
            lo, hi = s.raw_limits
            plo, phi = sorted((lo * s.scale + s.offset, hi * s.scale + s.offset))
            if s.min is not None:
                plo = max(plo, s.min)
            if s.max is not None:
                phi = min(phi, s.max)
            values[s.name] = draw(st.floats(plo, phi, allow_nan=False))
        return pname, m.name, values
    return build()


@functools.cache
def _decoder(name: str) -> CanDecoder:
    return CanDecoder(name)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_frame_values())
def test_encode_decode_round_trip_within_one_raw_step(case: tuple[str, str, dict[str, Any]]
                                                      ) -> None:
    pname, mname, values = case
    m = protocol(pname).message(mname)
    db = database(pname)
    dec = _decoder(pname)
    can = pytest.importorskip("can")
    for _, fid, _ in m.instances()[:2]:
        raw = {s.name: physical_to_raw(m.signal(s.name), values[s.name]) for s in m.signals}
        data = db.get_message_by_frame_id(fid).encode(raw, scaling=False, strict=False)
        assert len(data) == m.dlc
        rec = dec.decode(can.Message(arbitration_id=fid, data=data, is_extended_id=False), 0)
        assert rec["errors"] == [], rec["errors"]
        for s in m.signals:
            got, want = rec["fields"][s.name], values[s.name]
            if s.is_float:
                assert math.isclose(got, want, rel_tol=1e-6, abs_tol=1e-30)
            elif s.name not in rec["invalid"]:
                assert abs(got - want) <= abs(s.scale) + 1e-9 * max(1.0, abs(want)), s.name


def test_out_of_range_sends_invalid_or_clamps_as_the_spec_says() -> None:
    a = protocol("extlog2").message("Obstacle_Data_A")
    pos_x, rel_v = a.signal("Obstacle_Pos_X"), a.signal("Obstacle_Rel_Vel_X")
    assert pos_x.out_of_range == "invalid" and physical_to_raw(pos_x, 300.0) == 0xFFF
    assert physical_to_raw(pos_x, -1.0) == 0xFFF
    assert physical_to_raw(pos_x, MISSING) == 0xFFF
    assert rel_v.out_of_range == "clamp"
    assert physical_to_raw(rel_v, 500.0) == 2046  # 127.875: the largest step inside 127.93
    assert physical_to_raw(rel_v, MISSING) == -2048  # 0x800 in a 12-bit signed field
    yaw = protocol("extlog2").message("Lane").signal("Yaw_Angle")
    assert physical_to_raw(yaw, MISSING) == 0x7FFF  # no invalid value: physical 0
    assert physical_to_raw(yaw, float("nan")) == 0


def test_dbc_files_are_generated_not_hand_written() -> None:
    assert not list((ROOT / "specs").rglob("*.dbc"))
    assert yaml.safe_load((ROOT / "specs" / "can" / "extlog2.yaml").read_text())
