"""A conformance report a test engineer can sign: a header (side under test, address, SW
release seen, tool, suite, date), one overall verdict with its counts and what it means for
signing, and every case with its title, seed section, requirement, decisions and rule; the same
content in the console text, JSON Lines, JUnit XML, Markdown and HTML. A pass whose evidence
counts fewer successes than attempts says why it passes. Virtual time."""

from __future__ import annotations

import html
import json
import re
import xml.etree.ElementTree as ET

import pytest

from eyeq_spi.conformance import report
from eyeq_spi.conformance.cases import cases_for
from eyeq_spi.conformance.judges.verdict import Outcome, bad, ok, skip, unsure
from eyeq_spi.conformance.suite import Header, Options, Report, Result, run_report

HEADER = Header("eyeq", "tcp://10.0.0.7:5555", "EyeQ SW 9.0, MESP API 9.0 (reply #26)", "sw9",
                "eyeq-spi 0.1.0", "2026.11-4, 3 of its 58 cases for an EyeQ",
                "2026-11-29 03:00:00 UTC", "real")


def _report(*outcomes: Outcome) -> Report:
    cases = [c for c in cases_for("eyeq") if c.id in ("LINK-ACK", "DASP-COUNTER", "TP-FORMAT")]
    return Report(HEADER, [Result(c, o) for c, o in zip(cases, outcomes, strict=False)])


def _plain(text: str) -> str:
    return " ".join(text.split())


def _formats(rep: Report) -> dict[str, str]:
    """Every format as text a reader sees (markup unescaped, lines unfolded)."""
    junit = ET.fromstring(report.junit(rep, "s"))
    junit_text = " ".join([*(f"{e.get('name')} {e.get('value')}" for e in junit.iter("property")),
                           *(e.text or "" for e in junit.iter("system-out")),
                           *(e.get("name") or "" for e in junit.iter("testcase"))])
    return {"console": report.console(rep, width=80), "file": report.console(rep),
            "json": " ".join(str(v) for line in report.json_lines(rep).splitlines()
                             for v in json.loads(line).values()),
            "junit": junit_text, "markdown": report.markdown(rep, "t").replace("\\|", "|"),
            "html": html.unescape(re.sub(r"<[^>]+>", " ", report.html_report(rep, "t")))}


@pytest.mark.parametrize(("outcomes", "word"), [
    ((ok("fine"), ok("fine"), skip("not exercised")), "PASS"),
    ((ok("fine"), unsure("no DASP messages"), ok("fine")), "INCONCLUSIVE"),
    ((bad("late"), unsure("no DASP messages"), ok("fine")), "FAIL"),
])
def test_every_format_carries_header_verdict_and_cases(outcomes: tuple[Outcome, ...],
                                                       word: str) -> None:
    rep = _report(*outcomes)
    assert report.overall(rep.results) == word
    for name, text in _formats(rep).items():
        flat = _plain(text)
        for key, value in HEADER.rows():
            assert _plain(value) in flat, (name, key)
        assert word in flat and _plain(report.meaning(rep.results)) in flat, name
        for r in rep.results:
            c = r.case
            for part in (c.id, c.title, c.section, c.decision or "", c.rule,
                         r.outcome.evidence):
                assert _plain(part) in flat, (name, c.id, part)


def test_the_verdict_says_what_it_means_for_signing() -> None:
    open_ = _report(ok("fine"), unsure("no DASP messages"), ok("fine"))
    line = report.verdict_line(open_.results)
    assert line.startswith("VERDICT: INCONCLUSIVE (2 pass, 0 fail, 0 skip, 1 inconclusive")
    text = report.meaning(open_.results)
    assert "do not sign" in text and f"Inconclusive: {open_.results[1].case.id}" in text
    failed = _report(bad("late"), ok("fine"), ok("fine"))
    assert "Fail: LINK-ACK" in report.meaning(failed.results)
    assert report.exit_code(failed.results) == 1 and report.exit_code(open_.results) == 0


def test_the_console_reads_on_80_columns() -> None:
    rep = _report(bad("x " * 200), ok("fine"), skip("not exercised"))
    text = report.console(rep, width=80)
    lines = text.splitlines()
    assert max(len(line) for line in lines) <= 80
    assert lines[0] == "eyeq-spi conformance report"
    verdicts = [i for i, line in enumerate(lines) if line.startswith("VERDICT: FAIL")]
    first_case = next(i for i, line in enumerate(lines) if line.startswith("FAIL  LINK-ACK"))
    assert verdicts[0] < first_case < verdicts[-1]  # at the top and again at the end
    assert "§6 · MAPC-67290 · decisions L5 · timing rule" in text


@pytest.fixture(scope="module")
def eyeq_report() -> Report:
    return run_report(Options(dut="eyeq", builtin=True,
                              select="MESP-FN or LINK-NORESEND or LINK-SIZE"))


def test_the_header_of_a_run(eyeq_report: Report) -> None:
    h = eyeq_report.header
    assert h.dut == "eyeq" and h.address.startswith("built-in")
    assert re.fullmatch(r"EyeQ SW \d+\.\d+, MESP API \d+\.\d+ \(Get EyeQ Versions reply #\d+\)",
                        h.sw_seen), h.sw_seen
    assert h.tool.startswith("eyeq-spi ") and h.clock.startswith("virtual")
    assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC", h.date)
    assert f"of its {len(cases_for('eyeq'))} cases" in h.suite


def test_a_pass_that_counts_fewer_successes_says_why(eyeq_report: Report) -> None:
    """"2 of 4 request(s) answered" and "66 of them not ACKed" read like failures: each pass
    names what the others were."""
    for r in eyeq_report.results:
        assert r.outcome.verdict == "pass", (r.case.id, r.outcome)
        ev = r.outcome.evidence
        m = re.match(r"(\d+) of (\d+) request", ev)
        if m and m[1] != m[2]:
            assert f"the other {int(m[2]) - int(m[1])}: " in ev and "judged by" in ev, ev
    noresend = next(r for r in eyeq_report.results if r.case.id == "LINK-NORESEND")
    assert "resent none" in noresend.outcome.evidence
