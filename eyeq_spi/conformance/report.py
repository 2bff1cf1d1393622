"""Reporters: console text, JSON Lines, JUnit XML, Markdown and HTML, with the same content in
each (docs/conformance.md, "Contract")."""

from __future__ import annotations

import html
import json
import textwrap
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from eyeq_spi.conformance.judges.verdict import VERDICTS
from eyeq_spi.conformance.model import Case
from eyeq_spi.conformance.suite import Report, Result
from eyeq_spi.errors import EyeqError, UsageError

# what each overall verdict means to whoever signs the report
MEANING = {
    "PASS": "every case that ran passed; a skipped case names the rule this run did not "
            "exercise, and is no evidence either way",
    "FAIL": "the implementation under test broke a rule of seed 004 or of a decision: see the "
            "failed cases",
    "INCONCLUSIVE": "no case failed, but the inconclusive cases could not be judged in this "
                    "run: they show neither conformance nor a fault, so do not sign for their "
                    "rules until a rerun passes them (their evidence says what was missing)",
}


def summary(results: Sequence[Result]) -> dict[str, Any]:
    return {"kind": "summary",
            **{verdict: sum(r.outcome.verdict == verdict for r in results) for verdict in VERDICTS}}


def overall(results: Sequence[Result]) -> str:
    """PASS, FAIL or INCONCLUSIVE: a fail anywhere fails the run; else an inconclusive case
    leaves it open."""
    totals = summary(results)
    return "FAIL" if totals["fail"] else "INCONCLUSIVE" if totals["inconclusive"] else "PASS"


def exit_code(results: Sequence[Result]) -> int:
    return 1 if any(r.outcome.verdict == "fail" for r in results) else 0


def verdict_line(results: Sequence[Result]) -> str:
    totals = summary(results)
    counts = ", ".join(f"{totals[verdict]} {verdict}" for verdict in VERDICTS)
    return f"VERDICT: {overall(results)} ({counts}; {len(results)} cases)"


def meaning(results: Sequence[Result]) -> str:
    """What the overall verdict means for signing, and which cases it turns on."""
    text = MEANING[overall(results)]
    for verdict in ("fail", "inconclusive", "skip"):
        ids = [r.case.id for r in results if r.outcome.verdict == verdict]
        if ids:
            text += f". {verdict.capitalize()}: {', '.join(ids)}"
    return text + "."


def _refs(case: Case) -> str:
    """The seed section, requirement and decisions a case judges, and its kind of rule."""
    decisions = f"decisions {case.decision}" if case.decision else "no decision"
    return f"§{case.section} · {case.requirement or 'no MAPC ID'} · {decisions} · {case.rule} rule"


# -- JSON Lines -------------------------------------------------------------------------------
def json_lines(report: Report) -> str:
    lines = [json.dumps(report.header.as_json(), ensure_ascii=False)]
    lines += [json.dumps(result.as_json(), ensure_ascii=False) for result in report.results]
    verdict = overall(report.results)
    lines.append(json.dumps({**summary(report.results), "verdict": verdict,
                             "meaning": meaning(report.results)}, ensure_ascii=False))
    return "\n".join(lines)


# -- console ----------------------------------------------------------------------------------
def _fold(text: str, width: int | None, indent: int, first: int | None = None) -> list[str]:
    """``text`` folded between words to ``width`` (None: one line), its first line indented
    by ``first`` (default ``indent``) and the others by ``indent``."""
    start = " " * (indent if first is None else first)
    if width is None:
        return [start + text]
    return textwrap.wrap(text, width=max(width, 40), initial_indent=start,
                         subsequent_indent=" " * indent, break_long_words=False,
                         break_on_hyphens=False) or [start]


def console(report: Report, *, width: int | None = None) -> str:
    """The console report; with ``width`` (a terminal's columns) every line folds between
    words, without it (a file, a pipe) nothing folds."""
    results = report.results
    rows = ["eyeq-spi conformance report"]
    keyw = max(len(k) for k, _ in report.header.rows())
    for key, value in report.header.rows():
        folded = _fold(value, width, keyw + 4)
        rows.append(f"  {key:{keyw}s}  {folded[0].lstrip()}")
        rows += folded[1:]
    rows.append("")
    verdict = [*_fold(verdict_line(results), width, 2, 0), *_fold(meaning(results), width, 2)]
    rows += verdict
    for result in results:
        case = result.case
        rows.append("")
        rows += _fold(f"{result.outcome.verdict.upper()}  {case.id}  {case.title}", width, 4, 0)
        rows += _fold(_refs(case), width, 4)
        rows += _fold(result.outcome.evidence, width, 4)
    rows.append("")
    rows += verdict  # again at the end, where a terminal leaves the reader
    return "\n".join(rows)


def listing(cases: Sequence[Case]) -> str:
    rows = [f"{'ID':42s} {'DUT':9s} {'SECTION':10s} {'REQUIREMENT':24s} {'DECISION':9s} "
            f"{'RULE':7s} TITLE"]
    for case in cases:
        rows.append(f"{case.id:42s} {'/'.join(case.duts):9s} §{case.section:9s} "
                    f"{(case.requirement or '-'):24s} {(case.decision or '-'):9s} {case.rule:7s} "
                    f"{case.title}")
    return "\n".join(rows)


# -- JUnit ------------------------------------------------------------------------------------
def junit(report: Report, suite: str) -> bytes:
    results = report.results
    totals = summary(results)
    root = ET.Element("testsuites")
    ts = ET.SubElement(root, "testsuite", name=suite, tests=str(len(results)),
                       failures=str(totals["fail"]),
                       skipped=str(totals["skip"] + totals["inconclusive"]),
                       errors="0", timestamp=report.header.date)
    props = ET.SubElement(ts, "properties")
    for key, value in report.header.rows():
        ET.SubElement(props, "property", name=key, value=value)
    ET.SubElement(props, "property", name="verdict", value=overall(results))
    ET.SubElement(props, "property", name="meaning", value=meaning(results))
    for result in results:
        case = result.case
        tc = ET.SubElement(ts, "testcase", classname=f"{suite}.{case.group}", name=case.id)
        cprops = ET.SubElement(tc, "properties")
        for prop, text in (("title", case.title), ("section", case.section),
                           ("requirement", case.requirement or ""),
                           ("decision", case.decision or ""),
                           ("rule", case.rule), ("verdict", result.outcome.verdict)):
            ET.SubElement(cprops, "property", name=prop, value=text)
        verdict = result.outcome.verdict
        if verdict == "fail":
            ET.SubElement(tc, "failure", message=result.outcome.evidence[:200]).text = \
                result.outcome.evidence
        elif verdict in ("skip", "inconclusive"):
            ET.SubElement(tc, "skipped", message=f"{verdict}: {result.outcome.evidence}"[:400])
        ET.SubElement(tc, "system-out").text = f"{verdict}: {result.outcome.evidence}"
    ET.SubElement(ts, "system-out").text = f"{verdict_line(results)}\n{meaning(results)}"
    return bytes(ET.tostring(root, encoding="utf-8", xml_declaration=True))


# -- Markdown and HTML ------------------------------------------------------------------------
_COLUMNS = ("verdict", "case", "title", "§", "requirement", "decisions", "rule", "evidence")


def _cells(result: Result) -> list[str]:
    case = result.case
    return [result.outcome.verdict, case.id, case.title, case.section, case.requirement or "",
            case.decision or "", case.rule, result.outcome.evidence]


def _md(text: str) -> str:
    return text.replace("|", "\\|")


def markdown(report: Report, title: str) -> str:
    results = report.results
    out = [f"# {title}", "", "| | |", "|---|---|"]
    out += ["| " + " | ".join(_md(x) for x in row) + " |" for row in report.header.rows()]
    out += ["", f"**{verdict_line(results)}**", "", meaning(results), "",
            "| " + " | ".join(_COLUMNS) + " |", "|" + "---|" * len(_COLUMNS)]
    for result in results:
        out.append("| " + " | ".join(_md(x) for x in _cells(result)) + " |")
    return "\n".join(out) + "\n"


def html_report(report: Report, title: str) -> str:
    results = report.results
    colour = {"pass": "#d4f4d4", "fail": "#f8d0d0", "skip": "#eeeeee",
              "inconclusive": "#fff3c4"}
    head = "".join(f"<tr><th align=left>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>"
                   for k, v in report.header.rows())
    rows = []
    for result in results:
        tds = "".join(f"<td>{html.escape(x)}</td>" for x in _cells(result))
        rows.append(f'<tr style="background:{colour[result.outcome.verdict]}">{tds}</tr>')
    ths = "".join(f"<th>{h}</th>" for h in _COLUMNS)
    return (f"<!doctype html><meta charset=utf-8><title>{html.escape(title)}</title>"
            f"<h1>{html.escape(title)}</h1><table>{head}</table>"
            f"<p><strong>{html.escape(verdict_line(results))}</strong></p>"
            f"<p>{html.escape(meaning(results))}</p>"
            f"<table border=1 cellpadding=4 style='border-collapse:collapse'>"
            f"<tr>{ths}</tr>{''.join(rows)}</table>\n")


def write(path: str, data: str | bytes) -> None:
    try:
        Path(path).write_bytes(data.encode() if isinstance(data, str) else data)
    except OSError as exc:
        raise EyeqError(f"cannot write {path}: {exc}") from None


def write_report(path: str, report: Report, title: str) -> None:
    if path.endswith(".md"):
        write(path, markdown(report, title))
    elif path.endswith((".html", ".htm")):
        write(path, html_report(report, title))
    else:
        raise UsageError(f"--report {path}: use a .md or .html file name")
