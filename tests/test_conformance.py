"""The conformance suite against our own implementations in virtual time: every case
passes (LINK-GAP is judged on real time only), the CLI contract (list, -k, JSON, JUnit, report,
exit codes), and the judges on hand-made traces."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from eyeq_spi.cli import main
from eyeq_spi.conformance.cases import all_cases, cases_for
from eyeq_spi.conformance.judges.app import unused_masks
from eyeq_spi.conformance.judges.link import link_noresend, link_size
from eyeq_spi.conformance.judges.verdict import Context
from eyeq_spi.conformance.suite import Options, run, run_report, selector
from eyeq_spi.conformance.trace import Trace
from eyeq_spi.link.frame import FrameCodec

REALTIME_ONLY = {"LINK-GAP"}
# our host sends single frames only: the rules about several frames in flight are not exercised
NOT_EXERCISED = {"host": {"LINK-WINDOW", "LINK-TXTIMEOUT"}, "eyeq": set()}


@pytest.fixture(scope="module")
def eyeq_results():  # type: ignore[no-untyped-def]
    return run(Options(dut="eyeq", builtin=True))


@pytest.fixture(scope="module")
def host_results():  # type: ignore[no-untyped-def]
    return run(Options(dut="host", builtin=True))


@pytest.mark.parametrize("which", ["eyeq_results", "host_results"])
def test_builtin_passes_every_case(which: str, request: pytest.FixtureRequest) -> None:
    results = request.getfixturevalue(which)
    skips = REALTIME_ONLY | NOT_EXERCISED[which.split("_")[0]]
    bad = {r.case.id: r.outcome for r in results
           if r.outcome.verdict != "pass" and not (r.case.id in skips
                                                   and r.outcome.verdict == "skip")}
    assert not bad, bad
    gap = [r for r in results if r.case.id == "LINK-GAP"]
    assert gap and gap[0].outcome.verdict == "skip" and "real time" in gap[0].outcome.evidence
    assert all(r.outcome.evidence for r in results)


def test_cases_cite_sections_and_cover_the_groups() -> None:
    cases = all_cases()
    assert len({c.id for c in cases}) == len(cases)
    groups = {c.group for c in cases}
    assert groups == {"link", "transport", "mesp", "dasp", "flows", "host"}
    for c in cases:
        assert c.section and c.title
        assert c.requirement is None or c.requirement.startswith("MAPC-")
    ids = {c.id for c in cases_for("eyeq")}
    # one case per M3 function and one per DASP message and mode, from specs/
    assert {"MESP-FN-ComputeHash", "DASP-RATE-TAC-EYEQ_TAC_CAL_MSG",
            "DASP-RATE-APP-EYEQ_VIS_OBSTACLES_MSG"} <= ids
    assert "DASP-RATE-APP-HOST_VEH_STATE_MSG" in {c.id for c in cases_for("host")}


def test_selector_expressions() -> None:
    cases = cases_for("eyeq")
    pick = selector("link and not nak")
    chosen = {c.id for c in cases if pick(c)}
    assert "LINK-SIZE" in chosen and "LINK-NAK-CRC" not in chosen
    assert {c.id for c in cases if selector("(DIAG-RATE or TP-TID)")(c)} == {"DIAG-RATE",
                                                                             "TP-TID"}


def test_cli_list_json_junit_report_and_exit_codes(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["conformance", "--list"]) == 0
    out = capsys.readouterr().out
    assert "LINK-ACK" in out and "MAPC-67290" in out and "HOST-BOOT-RESETS" in out
    junit, report = tmp_path / "j.xml", tmp_path / "r.md"
    code = main(["conformance", "--dut", "host", "--builtin", "-k", "VERSIONS or REQTAG",
                 "--json", "--junit", str(junit), "--report", str(report)])
    assert code == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert [x["kind"] for x in lines] == ["header", "case", "case", "summary"]
    assert set(lines[0]) == {"kind", "dut", "side_under_test", "address", "sw_release_seen",
                             "tables_of_release", "time", "tool", "suite", "date"}
    assert set(lines[1]) == {"kind", "id", "title", "section", "requirement", "decision",
                             "rule", "verdict", "evidence"}
    assert {k: v for k, v in lines[-1].items() if k != "meaning"} == {
        "kind": "summary", "pass": 2, "fail": 0, "skip": 0, "inconclusive": 0, "verdict": "PASS"}
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None and suite.get("tests") == "2"
    assert "| pass | HOST-VERSIONS |" in report.read_text()
    # a broken variant: exit 1, the case fails in every output
    assert main(["conformance", "--dut", "host", "--builtin", "--mutant", "host-veh-50hz",
                 "-k", "HOST_VEH_STATE", "--json"]) == 1
    last = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert last["fail"] == 1
    for argv in (["conformance"], ["conformance", "--dut", "eyeq"],
                 ["conformance", "--dut", "eyeq", "--builtin", "-k", "nothing-matches-this"],
                 ["conformance", "--dut", "eyeq", "--builtin", "-k", "(("],
                 ["conformance", "--dut", "host", "--listen", "udp://x:1"],
                 ["conformance", "--dut", "eyeq", "--mutant", "eyeq-no-ack", "--port",
                  "socket://127.0.0.1:1"]):
        assert main(argv) == 2, argv
    assert "usage error" in capsys.readouterr().err


def test_connection_error_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["conformance", "--dut", "eyeq", "--port", "socket://127.0.0.1:1"]) == 2
    assert capsys.readouterr().err.startswith("eyeq-spi: error")


def _trace_with(frames: list[tuple[float, bytes]]) -> Trace:
    tr = Trace("eyeq")
    for t, raw in frames:
        tr.add(tr.dut_dir, t, raw)
    return tr


def test_judges_on_hand_made_traces() -> None:
    codec = FrameCodec()
    ctx = Context("eyeq", realtime=False)
    a = codec.data_frame(0, 5, b"\x00\x01\x41")
    assert link_size(ctx, _trace_with([(0.0, a), (0.001, a[:100])])).verdict == "fail"
    # the same NUM and bytes again 11 ms later is a resend (§6, L7)
    out = link_noresend(ctx, _trace_with([(0.0, a), (0.011, a)]))
    assert out.verdict == "fail" and "frame #0" in out.evidence
    assert link_noresend(ctx, _trace_with([(0.0, a)])).verdict == "pass"


def test_unused_bit_masks_come_from_the_layout() -> None:
    tr = Trace("host")
    lay = tr.codec.layout(tr.codec.cat.message("HOST_VEH_STATE_MSG"))
    masks = unused_masks(lay)
    assert masks and all(0 < m < (1 << (8 * s)) for _, s, m in masks)
    # the encoder sets them (D2): a zero-valued message passes
    data = lay.build(lay.zero_values())
    for off, size, mask in masks:
        assert int.from_bytes(data[off:off + size], "little") & mask == mask


def test_console_report_keeps_the_whole_evidence_and_fits_a_terminal() -> None:
    """The text report never cuts evidence: full lines for a file, folded for a terminal."""
    from eyeq_spi.conformance.report import console

    rep = run_report(Options(dut="eyeq", builtin=True,
                             select="LINK-CRC or LINK-ACK or DASP-RATE"))
    full = console(rep)
    for r in rep.results:
        assert r.outcome.evidence in full and f"§{r.case.section}" in full
    narrow = console(rep, width=80)
    assert max(len(line) for line in narrow.splitlines()) <= 80, narrow
    words = " ".join(narrow.split())
    for r in rep.results:
        assert " ".join(r.outcome.evidence.split()) in words
