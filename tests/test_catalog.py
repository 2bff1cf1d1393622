"""specs/ is data the tests enforce: schema, names from the seed, counts, SW resolution."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from eyeq_spi.catalog.link import specs_dir
from eyeq_spi.catalog.messages import catalog, normalise_sw
from eyeq_spi.catalog.schema import validate_tree
from eyeq_spi.codec.layout import LayoutCache

ROOT = Path(__file__).resolve().parents[1]
SEED = ROOT.parent / "shared" / "seeds" / "004_63c766cc38b57438.txt"
# The seed prints a heading but no table for eyeq_road_marking_speedlimit_t (§12.9, line 3583);
# its two position members are modelled on the crossing/arrow structs and flagged `invented`.
KNOWN_INVENTED = {("eyeq_road_marking_speedlimit_t", "sw5", "speedLimitLatPosition"),
                  ("eyeq_road_marking_speedlimit_t", "sw5", "speedLimitLongPosition")}


def squash(text: str) -> str:
    return re.sub(r"\s+", "", text).lower()


def all_docs() -> dict[Path, dict]:  # type: ignore[type-arg]
    return {p: yaml.safe_load(p.read_text()) for p in sorted(specs_dir().rglob("*.yaml"))}


def test_specs_validate_against_the_schema() -> None:
    assert validate_tree(specs_dir()) == []


def test_schema_validator_catches_broken_entries(tmp_path: Path) -> None:
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump({"structs": {"x_t": {"variants": {
        "sw5": {"seed_line": 1, "members": [
            {"name": "a", "type": "uint9", "seed_line": 1},
            {"name": "b", "type": "uint8", "bits": [3, 9], "seed_line": 1},
            {"name": "a", "type": "uint8", "seed_line": 1}]}}}}}))
    problems = validate_tree(tmp_path)
    assert any("unknown type 'uint9'" in p for p in problems)
    assert any("exceed uint8" in p for p in problems)
    assert any("duplicate name" in p for p in problems)



def test_a_message_outside_dasp_names_its_rule_a_protocol(tmp_path: Path) -> None:
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump({"other": [
        {"name": "EYEQ_DIAGNOSTIC_MSG", "data_id": 0x41}]}))
    assert any("protocol must be DIAG or BOOT" in p for p in validate_tree(tmp_path))


def test_rule_a_reads_the_first_byte_ids_from_the_spec() -> None:
    from eyeq_spi.codec.message import classify

    ids = {msg.protocol: msg.data_id for msg in catalog().messages if msg.protocol != "DASP"}
    assert ids == {"DIAG": 0x41, "BOOT": 0x10}
    assert [classify(bytes([ids["DIAG"], 0])), classify(bytes([ids["BOOT"], 0]))] == [
        "DIAG", "BOOT"]


@pytest.mark.skipif(not SEED.exists(), reason="the OCR'd seed texts are not beside the clone")
def test_every_member_name_occurs_in_the_seed() -> None:
    seed = squash(SEED.read_text(encoding="utf-8"))
    missing, invented = [], set()
    for path, doc in all_docs().items():
        rows = []
        for sname, s in (doc.get("structs") or {}).items():
            for vk, v in s["variants"].items():
                rows += [(sname, vk, m) for m in v["members"]]
        for iname, im in (doc.get("init_messages") or {}).items():
            for vk, v in (im.get("variants") or {}).items():
                rows += [(iname, vk, sig) for sig in v["signals"]]
        for owner, vk, m in rows:
            if m.get("invented"):
                assert m.get("reconstruction"), m["name"]
                invented.add((owner, vk, m["name"]))
                continue
            if "seed_form" in m:  # the literal OCR text; only with a reconstruction note
                assert m.get("reconstruction"), f"{owner}.{m['name']}: seed_form without a note"
            form = m.get("seed_form", m["name"])
            if squash(str(form)) not in seed:
                missing.append(f"{path.name}: {owner} {vk} {m['name']}")
    assert missing == []
    assert invented == KNOWN_INVENTED


def test_catalogue_counts() -> None:
    cat = catalog()
    n_variants = sum(len(s.variants) for s in cat.structs.values())
    n_members = sum(len(v.members) for s in cat.structs.values() for v in s.variants.values())
    assert len(cat.structs) >= 45 and n_variants >= 100 and n_members >= 1100
    assert len(cat.enums["traffic_sign"].values) >= 250
    dasp_ids = {m.data_id for m in cat.messages if m.protocol == "DASP"}
    assert dasp_ids == {0x20, 0xA0, 0xA1, 0xA2, 0xA3} | set(range(0xE0, 0xE9))
    assert {m.name for m in cat.mesp} >= {"GetEyeQExtendedState", "FFSReadFile", "ComputeHash"}
    assert {im.id for im in cat.init_messages.values()} >= {0x92, 0x85, 0x82, 0x78, 0x79, 0x84}
    assert cat.enums["fatal_error"].values[22]


def test_every_struct_variant_compiles_when_its_own_release_is_asked_for() -> None:
    cat = catalog()
    lc = LayoutCache(cat)
    for name, s in cat.structs.items():
        for key in s.variants:
            lay = lc.get(name, key)
            assert lay.variant == key and lay.size > 0


@pytest.mark.parametrize(("text", "key"), [("9.0", "sw9"), ("8.1", "sw8_1"), ("SW5", "sw5"),
                                           ("sw8_4", "sw8_4"), (None, "sw9")])
def test_sw_version_spellings(text: str | None, key: str) -> None:
    assert normalise_sw(text, "sw9") == key


def test_newest_layout_is_the_default() -> None:
    cat = catalog()
    lc = LayoutCache(cat)
    assert cat.default_sw == "sw9"
    assert lc.get("eyeq_vision_object_t", cat.sw(None)).variant == "sw9"
    assert lc.get("eyeq_vision_object_t", "sw8_3").variant == "sw8_1"
    assert lc.get("host_vehicle_state_t", "sw8_1").variant == "sw8"
