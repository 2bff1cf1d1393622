"""Reporters: console text, JSON Lines, JUnit XML, Markdown and HTML, with the same content in
each: the header (side under test, address, SW release seen, tool, suite, date), one overall
verdict with its counts and what it means for signing, then every case with its title, seed
section, requirement, decisions, rule (timing or content), verdict and evidence
(docs/conformance.md)."""

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
    out: dict[str, Any] = {"kind": "summary"}
    for v in VERDICTS:
        out[v] = sum(r.outcome.verdict == v for r in results)
    return out


def overall(results: Sequence[Result]) -> str:
    """PASS, FAIL or INCONCLUSIVE: a fail anywhere fails the run; else an inconclusive case
    leaves it open."""
    s = summary(results)
    return "FAIL" if s["fail"] else "INCONCLUSIVE" if s["inconclusive"] else "PASS"


def exit_code(results: Sequence[Result]) -> int:
    return 1 if any(r.outcome.verdict == "fail" for r in results) else 0


def verdict_line(results: Sequence[Result]) -> str:
    s = summary(results)
    counts = ", ".join(f"{s[v]} {v}" for v in VERDICTS)
    return f"VERDICT: {overall(results)} ({counts}; {len(results)} cases)"


def meaning(results: Sequence[Result]) -> str:
    """What the overall verdict means for signing, and which cases it turns on."""
    text = MEANING[overall(results)]
    for v in ("fail", "inconclusive", "skip"):
        ids = [r.case.id for r in results if r.outcome.verdict == v]
        if ids:
            text += f". {v.capitalize()}: {', '.join(ids)}"
    return text + "."


def _refs(c: Case) -> str:
    """The seed section, requirement and decisions a case judges, and its kind of rule."""
    decisions = f"decisions {c.decision}" if c.decision else "no decision"
    return f"§{c.section} · {c.requirement or 'no MAPC ID'} · {decisions} · {c.rule} rule"


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
    """The header, the overall verdict and what it means, then each case: verdict, ID and
    title; the references it judges; its evidence in full. With ``width`` (a terminal's
    columns) every line folds between words; without it (a file, a pipe) nothing folds."""
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
    for r in results:
        c = r.case
        rows.append("")
        rows += _fold(f"{r.outcome.verdict.upper()}  {c.id}  {c.title}", width, 4, 0)
        rows += _fold(_refs(c), width, 4)
        rows += _fold(r.outcome.evidence, width, 4)
    rows.append("")
    rows += verdict  # again at the end, where a terminal leaves the reader
    return "\n".join(rows)


def listing(cases: Sequence[Case]) -> str:
    rows = [f"{'ID':42s} {'DUT':9s} {'SECTION':10s} {'REQUIREMENT':24s} {'DECISION':9s} "
            f"{'RULE':7s} TITLE"]
    for c in cases:
        rows.append(f"{c.id:42s} {'/'.join(c.duts):9s} §{c.section:9s} "
                    f"{(c.requirement or '-'):24s} {(c.decision or '-'):9s} {c.rule:7s} "
                    f"{c.title}")
    return "\n".join(rows)


# -- JUnit ------------------------------------------------------------------------------------
def junit(report: Report, suite: str) -> bytes:
    results = report.results
    s = summary(results)
    root = ET.Element("testsuites")
    ts = ET.SubElement(root, "testsuite", name=suite, tests=str(len(results)),
                       failures=str(s["fail"]), skipped=str(s["skip"] + s["inconclusive"]),
                       errors="0", timestamp=report.header.date)
    props = ET.SubElement(ts, "properties")
    for key, value in report.header.rows():
        ET.SubElement(props, "property", name=key, value=value)
    ET.SubElement(props, "property", name="verdict", value=overall(results))
    ET.SubElement(props, "property", name="meaning", value=meaning(results))
    for r in results:
        c = r.case
        tc = ET.SubElement(ts, "testcase", classname=f"{suite}.{c.group}", name=c.id)
        cprops = ET.SubElement(tc, "properties")
        for k, v in (("title", c.title), ("section", c.section),
                     ("requirement", c.requirement or ""), ("decision", c.decision or ""),
                     ("rule", c.rule), ("verdict", r.outcome.verdict)):
            ET.SubElement(cprops, "property", name=k, value=v)
        v = r.outcome.verdict
        if v == "fail":
            ET.SubElement(tc, "failure", message=r.outcome.evidence[:200]).text = \
                r.outcome.evidence
        elif v in ("skip", "inconclusive"):
            ET.SubElement(tc, "skipped", message=f"{v}: {r.outcome.evidence}"[:400])
        ET.SubElement(tc, "system-out").text = f"{v}: {r.outcome.evidence}"
    ET.SubElement(ts, "system-out").text = f"{verdict_line(results)}\n{meaning(results)}"
    return bytes(ET.tostring(root, encoding="utf-8", xml_declaration=True))


# -- Markdown and HTML ------------------------------------------------------------------------
_COLUMNS = ("verdict", "case", "title", "§", "requirement", "decisions", "rule", "evidence")


def _cells(r: Result) -> list[str]:
    c = r.case
    return [r.outcome.verdict, c.id, c.title, c.section, c.requirement or "", c.decision or "",
            c.rule, r.outcome.evidence]


def _md(text: str) -> str:
    return text.replace("|", "\\|")


def markdown(report: Report, title: str) -> str:
    results = report.results
    out = [f"# {title}", "", "| | |", "|---|---|"]
    out += ["| " + " | ".join(_md(x) for x in row) + " |" for row in report.header.rows()]
    out += ["", f"**{verdict_line(results)}**", "", meaning(results), "",
            "| " + " | ".join(_COLUMNS) + " |", "|" + "---|" * len(_COLUMNS)]
    for r in results:
        out.append("| " + " | ".join(_md(x) for x in _cells(r)) + " |")
    return "\n".join(out) + "\n"


def html_report(report: Report, title: str) -> str:
    results = report.results
    colour = {"pass": "#d4f4d4", "fail": "#f8d0d0", "skip": "#eeeeee",
              "inconclusive": "#fff3c4"}
    head = "".join(f"<tr><th align=left>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>"
                   for k, v in report.header.rows())
    rows = []
    for r in results:
        tds = "".join(f"<td>{html.escape(x)}</td>" for x in _cells(r))
        rows.append(f'<tr style="background:{colour[r.outcome.verdict]}">{tds}</tr>')
    ths = "".join(f"<th>{h}</th>" for h in _COLUMNS)
    return (f"<!doctype html><meta charset=utf-8><title>{html.escape(title)}</title>"
            f"<h1>{html.escape(title)}</h1><table>{head}</table>"
            f"<p><strong>{html.escape(verdict_line(results))}</strong></p>"
            f"<p>{html.escape(meaning(results))}</p>"
            f"<table border=1 cellpadding=4 style='border-collapse:collapse'>"
            f"<tr>{ths}</tr>{''.join(rows)}</table>\n")


def write(path: str, data: str | bytes) -> None:
    try:
        p = Path(path)
        if isinstance(data, bytes):
            p.write_bytes(data)
        else:
            p.write_text(data, encoding="utf-8")
    except OSError as exc:
        raise EyeqError(f"cannot write {path}: {exc}") from None


def write_report(path: str, report: Report, title: str) -> None:
    if path.endswith(".md"):
        write(path, markdown(report, title))
    elif path.endswith((".html", ".htm")):
        write(path, html_report(report, title))
    else:
        raise UsageError(f"--report {path}: use a .md or .html file name")
