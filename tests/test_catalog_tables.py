"""Seed content found missing from specs/, and decisions D6/M7/M2/M3 as data: checked
against the seed text (OCR'd seed 004) and PROTOCOL_DECISIONS.md like tests/test_catalog.py does."""

from __future__ import annotations

import io
import re
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from eyeq_spi.catalog.link import spec_file, specs_dir
from eyeq_spi.catalog.messages import catalog
from eyeq_spi.catalog.schema import validate_tree
from eyeq_spi.catalog.tables import alignment_nvm, dasp_header, decisions, gpio_groups
from eyeq_spi.codec.describe import spec_show
from eyeq_spi.codec.layout import LayoutCache
from eyeq_spi.codec.message import DASP_PROTOCOL, MessageCodec
from eyeq_spi.dissect.engine import _enum_plan
from eyeq_spi.dissect.output import HumanWriter
from eyeq_spi.errors import SpecError

ROOT = Path(__file__).resolve().parents[1]
SEEDS = ROOT.parent / "shared"
SEED = SEEDS / "seeds" / "004_63c766cc38b57438.txt"
DECISIONS_MD = SEEDS / "PROTOCOL_DECISIONS.md"
needs_seed = pytest.mark.skipif(not SEED.exists(),
                                reason="the OCR'd seed texts are not beside the clone")
needs_decisions = pytest.mark.skipif(not DECISIONS_MD.exists(),
                                     reason="the decisions file is not beside the clone")


def squash(text: str) -> str:
    return re.sub(r"\s+", "", text).lower()


def seed_line(n: int) -> str:
    return SEED.read_text(encoding="utf-8").splitlines()[n - 1]


def on_line(text: str, n: int) -> bool:
    return squash(text) in squash(seed_line(n))


def enum_doc(name: str) -> dict[str, Any]:
    for path in sorted((specs_dir() / "enums").glob("*.yaml")):
        doc = yaml.safe_load(path.read_text())
        if name in doc.get("enums", {}):
            return dict(doc["enums"][name])
    raise KeyError(name)


# -- D6, M7 ---------------------------------------------------------------------------------------
def test_d6_app_diag_status_is_in_every_release_with_one_payload() -> None:
    cat = catalog()
    lc = LayoutCache(cat)
    sizes = set()
    for sw in cat.sw_versions:
        msg = cat.dasp_by_id(0xA1, sw)
        assert msg is not None and msg.name == "EYEQ_APP_DIAG_STATUS_MSG", sw
        sizes.add(lc.get(msg.payload, sw).size)
    assert len(sizes) == 1
    raw = next(m for m in spec_file("messages.yaml")["dasp"] if m["data_id"] == 0xA1)
    assert raw["until"] is None and raw["decision"] == "D6"


@needs_seed
def test_d6_rests_on_the_sw6_message_table_and_the_payload_heading() -> None:
    assert on_line("0xA1\tEYEQ_APP_DIAG_STATUS_MSG", 1413)
    assert "MAPC-67370" in seed_line(1405) and "SW6.0 AND LATER" in seed_line(1405)
    assert "FOR SW6.0 and EARLIER RELEASES" in seed_line(1485)


def test_m7_dv_is_main_state_0xaa_and_application_id_5() -> None:
    cat = catalog()
    main = cat.enums["main_state"]
    assert main.values[0xAA].name == "RUNNING_DV"
    assert 0x05 not in main.values  # "DV mode == 0x5" is the application ID (M7)
    assert cat.enums["eyeq_application"].values[0x05].name == "DV"
    raw = enum_doc("main_state")
    assert raw["decision"] == "M7"
    assert next(v for v in raw["values"] if v["value"] == 0xAA)["decision"] == "M7"


@needs_seed
def test_m7_value_is_the_0x41_table_row() -> None:
    assert on_line("0xAA = RUNNING_DV", 1655)
    assert on_line("N/A = PENDING_INIT_DV", 1654)


# -- decisions restated in specs/ -----------------------------------------------------------------
def test_new_decisions_are_restated_in_specs() -> None:
    assert {"L6a", "L9", "L10", "L10a", "D6", "M7", "M2", "M3"} <= set(decisions())


@needs_decisions
def test_restated_decisions_follow_protocol_decisions_md() -> None:
    """Each decision of specs/decisions.yaml says what the normative PROTOCOL_DECISIONS.md says;
    the project's own refinements (T6a), which that file does not have, what
    docs/PROTOCOL_DECISIONS.md says."""
    shared = DECISIONS_MD.read_text(encoding="utf-8")
    ours = (ROOT / "docs" / "PROTOCOL_DECISIONS.md").read_text(encoding="utf-8")
    for d in decisions().values():
        pattern = rf"\*\*{re.escape(d.id)}\. (.*?)(?=\n\*\*[A-Z]\d+[a-z]?\. |\n## |\Z)"
        m = re.search(pattern, shared, re.S) or re.search(pattern, ours, re.S)
        assert m, d.id
        theirs = set(re.findall(r"[a-z0-9]+", m.group(1).lower()))
        ours = re.findall(r"[a-z0-9]+", d.text.lower())
        missing = [w for w in ours if w not in theirs]
        assert len(missing) <= len(ours) // 10, (d.id, missing)


def test_unknown_decision_ids_are_schema_problems(tmp_path: Path) -> None:
    (tmp_path / "decisions.yaml").write_text(yaml.safe_dump(
        {"decisions": [{"id": "D6", "title": "t", "text": "x"}]}))
    (tmp_path / "e.yaml").write_text(yaml.safe_dump({"enums": {"e": {"values": [
        {"value": 1, "name": "A", "decision": "Q9"}, {"value": 2, "name": "B", "decision": "D6"},
        {"value": 3, "name": "C", "decision": "a prose note is not an id"}]}}}))
    problems = validate_tree(tmp_path)
    assert [p for p in problems if "decision" in p] == [
        "e.yaml/enums/e/values[A]: decision Q9 is not in decisions.yaml"]


# -- MESP M2/M3 -----------------------------------------------------------------------------------
def test_mesp_return_codes_are_seed_for_success_and_m2_for_failures() -> None:
    rets = spec_file("mesp.yaml")["mesp_ret"]
    assert rets[0]["seed_line"] == 679 and "decision" not in rets[0]
    assert {c: r["decision"] for c, r in rets.items() if c} == {c: "M2" for c in range(1, 6)}
    assert catalog().mesp_ret == {0: "SUCCESS", 1: "GENERAL_FAILURE",
                                  2: "UNKNOWN_SERVICE_OR_FUNCTION", 3: "BAD_PARAMETERS",
                                  4: "NOT_ALLOWED_IN_STATE", 5: "FILE_NOT_FOUND"}


@needs_seed
def test_mesp_parameters_say_where_they_come_from() -> None:
    assert on_line("ret == 0", 679)
    funcs = {f["name"]: f for f in spec_file("mesp.yaml")["mesp_functions"]}
    switch = funcs["SwitchEyeQApplication"]
    assert [p["decision"] for p in switch["request"] + switch["reply"]] == ["M3", "M3"]
    assert "Ref[1] Section 3.6.6" in seed_line(switch["reply"][0]["seed_line"])
    for f in funcs.values():
        head = seed_line(f["seed_line"]).replace("OvSE", "0x5E").replace("0v", "0x")
        assert head.startswith(f"0x{f['service']:02X}\t0x5E"), f["name"]
        for p in f["request"] + f["reply"]:
            assert "seed_line" in p or "decision" in p
            if "decision" not in p:  # read from the seed: its name is on its line
                assert seed_line(p["seed_line"]).startswith(p["name"]), (f["name"], p["name"])


# -- supplemental traffic signs -------------------------------------------------------------------
ISSUE_SUPPLEMENTAL = {0: "none", 9: "truck", 11: "weight", 12: "tractor", 17: "fog",
                      18: "hazardous_materials", 19: "night", 20: "supp_sign_generic",
                      27: "minimum", 28: "reduced_ahead", 29: "distance_stop", 30: "par_verglas",
                      31: "ahead"}


def test_supplemental_signs_are_the_legible_values_and_type_the_tsr_members() -> None:
    cat = catalog()
    sup = cat.enums["supplemental_sign"]
    assert {k: v.name for k, v in sup.values.items()} == {
        k: f"e_{n}" for k, n in ISSUE_SUPPLEMENTAL.items()}
    assert sup.complete is False
    variants = cat.structs["eyeq_traffic_sign_t"].variants.values()
    typed = [(m.name, m.enum) for v in variants for m in v.members if "Supplemental" in m.name]
    assert typed and set(typed) == {("signSupplementalType1", "supplemental_sign"),
                                    ("signSupplementalType2", "supplemental_sign")}


def test_an_incomplete_enum_is_not_checked_by_the_dissector() -> None:
    codec = MessageCodec("9.0")
    lay = codec.layouts.get("eyeq_traffic_sign_t", codec.sw)
    checked = {name for name, enum, _child, _arr in _enum_plan(codec, lay) if enum is not None}
    assert "signType" in checked
    assert not checked & {"signSupplementalType1", "signSupplementalType2"}


@needs_seed
def test_supplemental_values_are_read_from_their_seed_lines() -> None:
    assert "Definition of supplemental traffic signs" in seed_line(4562)
    for v in enum_doc("supplemental_sign")["values"]:
        form = v.get("seed_form", v["name"])
        assert on_line(form, v["seed_line"]), v["name"]
        assert form == f"E_EYEQ_TSR_{v['name']}" + (f" = {v['value']}," if "=" in form else "")
        if "=" not in form:  # value on another line: say so
            assert v.get("reconstruction")


# -- 0x41 flags -----------------------------------------------------------------------------------
def test_video_error_flags_type_camera1_and_name_set_bits() -> None:
    cat = catalog()
    flags = cat.enums["video_error_flags"]
    assert flags.kind == "flags"
    assert set(flags.values) == set(range(28)) - {7, 8, 23}
    word = 0x1 | 0x2000 | 0x8000000
    assert flags.label(word) == "VDI_VIDEO_ERROR|VDI_ERR_TIMEOUT|SHOT_OUT_OF_SYNC"
    assert flags.label(0) is None  # NO_VIDEO_ERROR
    for key, var in cat.structs["EYEQ_DIAGNOSTIC_MSG"].variants.items():
        enums = {m.name: m.enum for m in var.members}
        assert enums["Camera1_VideoErrorFlags"] == "video_error_flags", key
        assert enums["Camera2_VideoErrorFlags"] is None, key  # "TBD" in the seed



def test_dissect_tree_names_the_set_bits_of_0x41() -> None:
    codec = MessageCodec("8.3")
    msg = codec.cat.message("EYEQ_DIAGNOSTIC_MSG")
    fields = codec.layout(msg).zero_values()
    fields.update(Main_State=0xAA, Camera1_VideoErrorFlags=0x2000 | 0x4,
                  Application_Diagnostics_part_2=1 << 6 | 2 << 3)
    out = codec.decode(codec.encode_other("DIAG", fields))
    assert out.ok, out.errors
    fh = io.StringIO()
    HumanWriter(fh, codec, color=False).write(
        {"kind": "message", "protocol": out.protocol, "name": out.name, "length": out.length,
         "header": out.header, "errors": out.errors, "fields": out.fields})
    text = fh.getvalue()
    assert "Main_State = 170 (RUNNING_DV)" in text
    assert "Camera1_VideoErrorFlags = 8196 (LOGICAL_VIDEO_ERROR|VDI_ERR_TIMEOUT)" in text
    assert ("Application_Diagnostics_part_2 = 80 "
            "(DDR_CLOCK_DRIFT_WARNINGS=DRIFT_TOO_LATE|INTERNAL_INIT)") in text
    assert "Camera2_VideoErrorFlags = 0\n" in text and "undefined" not in text

@needs_seed
def test_video_error_flags_are_read_from_their_seed_lines() -> None:
    legible = 0
    for v in enum_doc("video_error_flags")["values"]:
        form = v.get("seed_form", v["name"])
        assert on_line(form, v["seed_line"]), v["name"]
        if "reconstruction" not in v:  # read literally: name and hex value on the line
            assert squash(f"{v['name']}={1 << v['bit']:#x}") in squash(seed_line(v["seed_line"]))
            legible += 1
    assert legible >= 5


def test_app_diagnostics_part2_changes_with_sw8_3() -> None:
    cat = catalog()
    lc = LayoutCache(cat)
    old, new = lc.get("EYEQ_DIAGNOSTIC_MSG", "sw8_1"), lc.get("EYEQ_DIAGNOSTIC_MSG", "sw8_3")
    assert (old.variant, new.variant) == ("sw6", "sw8_3")
    assert [(f.name, f.offset, f.size) for f in old.fields] == \
        [(f.name, f.offset, f.size) for f in new.fields]
    assert old.field("Application_Diagnostics_part_2").member.enum == "app_diagnostic_part2"
    assert new.field("Application_Diagnostics_part_2").member.enum == "app_diagnostic_part2_sw8_3"
    part2 = cat.enums["app_diagnostic_part2_sw8_3"]
    word = 1 << 1 | 3 << 3 | 1 << 7
    assert part2.label(word) == ("DDR_REFRESH_RATE=E_DDR_MODE_HIGH_REFRESH_RATE|"
                                 "DDR_CLOCK_DRIFT_WARNINGS=DRIFT_TIMEOUT_WR|BRAIN_DROP")
    assert part2.label(5 << 3) == "DDR_CLOCK_DRIFT_WARNINGS=5"  # unnamed value: its number
    assert cat.enums["app_diagnostic_part2"].label(1 << 2) == "E_DDR_MODE_HIGH_REFRESH_RATE"
    shown = spec_show(cat, "app_diagnostic_part2_sw8_3", "sw9")
    assert "bits 3-5  DDR_CLOCK_DRIFT_WARNINGS" in shown


@needs_seed
def test_app_diagnostics_part2_bits_are_read_from_the_seed() -> None:
    assert "FOR SW8.3 and LATER RELEASES" in seed_line(1896)
    for v in enum_doc("app_diagnostic_part2_sw8_3")["values"]:
        line = seed_line(v["seed_line"])
        bits = v.get("bits", [v.get("bit")] * 2)
        cell = str(bits[0]) if bits[0] == bits[1] else f"{bits[0]}-{bits[1]}"
        assert squash(v.get("seed_form", v["name"].replace("_", " "))) in squash(line)
        assert squash(f"\t{cell}\t") in squash(line.replace(" ", "")), v["name"]
    assert on_line("E_DDR_MODE_HIGH_REFRESH_RATE = 1", 1878)


def test_overlapping_flag_fields_are_schema_problems(tmp_path: Path) -> None:
    (tmp_path / "e.yaml").write_text(yaml.safe_dump({"enums": {"f": {"kind": "flags", "values": [
        {"bits": [1, 3], "name": "A", "values": {0: "X", 9: "TOO_BIG"}}, {"bit": 2, "name": "B"},
        {"bits": [5, 4], "name": "C"}]}}}))
    problems = validate_tree(tmp_path)
    assert any("values must map" in p for p in problems)
    assert any("bit 2 repeated" in p for p in problems)
    assert any("bits must be [lo, hi]" in p for p in problems)


# -- DASP header ----------------------------------------------------------------------------------
def test_dasp_header_is_data_and_the_codec_uses_it() -> None:
    h = dasp_header()
    assert h.protocol == DASP_PROTOCOL == 0x65
    assert [(f.name, f.offset, f.value) for f in h.fields] == [
        ("Protocol", 0, 0x65), ("DataID", 1, None), ("Counter", 2, None), ("RESERVED", 3, 0)]
    assert h.size == 4 and h.counter_modulo == 256 and h.unused_bits == 1
    assert h.reserved_data_ids == {0x5E}
    assert all(m.data_id not in h.reserved_data_ids for m in catalog().messages)
    codec = MessageCodec("9.0")
    msg = codec.message("EYEQ_APP_DIAG_STATUS_MSG")
    lay = codec.layout(msg)
    wire = codec.encode_dasp(msg.name, lay.zero_values(), counter=7)
    assert wire[:h.size] == bytes([0x65, 0xA1, 7, 0])
    assert len(wire) == h.size + lay.size
    base = catalog().structs["EYEQ_BASE_DIAG_STATUS_MSG"].variants["sw2_2"]
    assert {h.bad_sequence_counter, h.bad_length_counter} <= {m.name for m in base.members}


@needs_seed
def test_dasp_header_is_read_from_section_7_1_2() -> None:
    assert seed_line(1001).startswith("0x65\tData ID\tCounter\tRESERVED")
    assert "**0x65**" in seed_line(1005)
    assert "Data ID 0x5E" in seed_line(1007)
    assert "from 0 to 255" in seed_line(1009) and "eyeqSPIMsgRxBadSeqCtr" in seed_line(1009)
    assert "set to 1" in seed_line(1011) and "eyeqSPIMsgRxBadHdrCtr" in seed_line(1011)


# -- Appendix D GPIO ------------------------------------------------------------------------------
def test_gpio_groups_and_the_boot_stage_they_share_with_message_0x10() -> None:
    groups = gpio_groups()
    assert list(groups) == ["boot_diagnostics", "hardware_id", "core_dump", "camera_select",
                            "errout", "time_sync"]
    boot = groups["boot_diagnostics"]
    stages = catalog().enums["boot_stage"].values
    for code in range(1, 6):
        assert stages[code].name.startswith(boot.values[code]), code
    assert groups["camera_select"].direction == "host_to_eyeq"
    assert groups["hardware_id"].values[2] == "DV" and len(groups["hardware_id"].encoding) == 4


@given(st.sampled_from(sorted(gpio_groups())), st.integers(0, 15))
def test_gpio_levels_and_codes_round_trip(name: str, code: int) -> None:
    g = gpio_groups()[name]
    if code >= 1 << len(g.encoding):
        with pytest.raises(SpecError):
            g.levels(code)
        return
    levels = g.levels(code)
    assert g.code(levels) == code
    assert levels[g.encoding[-1]] == code & 1  # last pin listed is the least significant bit


def test_gpio_code_rejects_a_missing_pin() -> None:
    with pytest.raises(SpecError, match="EYEQ4_AURIX_BOOT_0"):
        gpio_groups()["boot_diagnostics"].code({"EYEQ4_AURIX_BOOT_2": 1, "EYEQ4_AURIX_BOOT_1": 0})


@needs_seed
def test_gpio_pins_and_values_are_on_their_seed_lines() -> None:
    assert "APPENDIX D: GPIO Definitions" in seed_line(4930)
    for g in spec_file("gpio.yaml")["gpio"]["groups"]:
        assert on_line(g.get("seed_form", g["name"]), g["seed_line"]), g["name"]
        for p in g["pins"]:
            line = seed_line(p["seed_line"])
            if "seed_form" in p:
                assert p.get("reconstruction") and squash(p["seed_form"]) in squash(line)
            else:
                assert squash(f"{p['label']}\t{p['gpio']}\t{p['ball']}") in squash(line)
        for v in g["values"]:
            line = seed_line(v["seed_line"])
            words = v.get("seed_form", v.get("description", v["name"].replace("_", " ")))
            if "reconstruction" not in v:
                assert squash(f"{v['value']} = {words}") in squash(line), (g["name"], v)


# -- §21 Alignment NVM ----------------------------------------------------------------------------
def test_alignment_nvm_rows_apply_as_the_table_says() -> None:
    nvm = alignment_nvm()
    assert [p.name for p in nvm.parameters] == ["horizonKA", "yawKA", "rollAngleKA",
                                                "cameraAlignmentValidKA"]
    stored = {"horizonKA": 1.0, "yawKA": 2.0, "rollAngleKA": 0.5, "cameraAlignmentValidKA": 0.0}
    measured = {"distPitch": -3, "distYaw": 4, "roll": 1.25}
    assert nvm.apply("TAC", stored, measured) == {
        "horizonKA": -3.0, "yawKA": 4.0, "rollAngleKA": 1.25, "cameraAlignmentValidKA": 1.0}
    assert nvm.apply("SPC", stored, measured)["rollAngleKA"] == 0.0
    assert nvm.apply("Autofix", stored, measured)["rollAngleKA"] == 0.5
    assert nvm.source("autofix").run_mode == "AUTOFIX"
    with pytest.raises(SpecError, match="no calibration source"):
        nvm.source("EOL")
    with pytest.raises(SpecError, match="lacks distPitch"):
        nvm.apply("TAC", stored, {"distYaw": 1, "roll": 0})
    init = nvm.init_values({"horizonKA": 2.0, "yawKA": -1.0, "rollAngleKA": 180.0,
                            "cameraAlignmentValidKA": 1.0})
    assert init["horizonFull"] == 2.0 and init["cameraAlignmentValid"] == 1.0
    assert init["rollAngle"] == pytest.approx(3.141592653589793)
    assert nvm.defaults() == dict.fromkeys(stored, 0.0)


@given(st.sampled_from(["TAC", "SPC", "Autofix"]),
       st.lists(st.floats(-500, 500), min_size=4, max_size=4),
       st.lists(st.floats(-500, 500), min_size=3, max_size=3))
def test_alignment_nvm_only_touches_what_its_row_names(source: str, old: list[float],
                                                       new: list[float]) -> None:
    nvm = alignment_nvm()
    stored = dict(zip([p.name for p in nvm.parameters], old, strict=True))
    measured = dict(zip(["distPitch", "distYaw", "roll"], new, strict=True))
    out = nvm.apply(source, stored, measured)
    for p in nvm.parameters:
        action = nvm.source(source).actions[p.name]
        expect = {"keep": stored[p.name], "set_zero": 0.0,
                  "update": measured.get(p.source or "", 1.0)}[action]
        assert out[p.name] == expect


@needs_seed
def test_alignment_nvm_is_the_section_21_table() -> None:
    doc = spec_file("nvm.yaml")["alignment_nvm"]
    assert "Alignment NVM Table" in seed_line(doc["seed_line"])
    assert seed_line(4968).split() == [p["name"] for p in doc["parameters"]]
    cell = {"update": "update", "set_zero": "set to be 0", "keep": "update"}
    for s in doc["sources"]:
        row = seed_line(s["seed_line"]).split("\t")
        assert row[0] == s["name"]
        assert [c.strip() for c in row[1:5]] == [cell[a] for a in s["actions"].values()]
    assert seed_line(4971).split("\t")[3] == "do not"  # the keep cell: "do not" / "update"
    assert seed_line(doc["rule"]["seed_line"]) == doc["rule"]["text"]


def test_nvm_cross_references_are_checked(tmp_path: Path) -> None:
    doc = spec_file("nvm.yaml")
    bad = yaml.safe_load(yaml.safe_dump(doc))
    bad["alignment_nvm"]["sources"][0]["actions"].pop("yawKA")
    bad["alignment_nvm"]["sources"][1]["success"] = {"status": "FINISHED"}
    bad["alignment_nvm"]["parameters"][0]["init_signal"] = "horizonHalf"
    for name in ("structs/diag_types.yaml", "enums/host_diag.yaml", "messages.yaml",
                 "init/init_params_vision.yaml", "sw_versions.yaml", "constants.yaml"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text((specs_dir() / name).read_text())
    (tmp_path / "nvm.yaml").write_text(yaml.safe_dump(bad))
    problems = [p for p in validate_tree(tmp_path) if p.startswith("nvm.yaml")]
    assert any("actions must name every parameter" in p for p in problems)
    assert any("'FINISHED' is not a value of its enum" in p for p in problems)
    assert any("'horizonHalf' is no Init_Params_Vision signal" in p for p in problems)
