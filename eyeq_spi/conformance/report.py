"""Reporters: console table, JSON Lines (one object per case, then the summary, as
docs/conformance.md describes), JUnit XML, Markdown and HTML."""

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
from eyeq_spi.conformance.suite import Result
from eyeq_spi.errors import EyeqError, UsageError


def summary(results: Sequence[Result]) -> dict[str, Any]:
    out: dict[str, Any] = {"kind": "summary"}
    for v in VERDICTS:
        out[v] = sum(r.outcome.verdict == v for r in results)
    return out


def exit_code(results: Sequence[Result]) -> int:
    return 1 if any(r.outcome.verdict == "fail" for r in results) else 0


def json_lines(results: Sequence[Result]) -> str:
    lines = [json.dumps(r.record(), ensure_ascii=False) for r in results]
    lines.append(json.dumps(summary(results)))
    return "\n".join(lines)


def console(results: Sequence[Result], *, width: int | None = None) -> str:
    """One line per case: verdict, ID, the seed section it cites, its evidence in full. With
    ``width`` (a terminal's columns) the evidence folds between words under its case; without
    it (a file, a pipe) every case stays on one line."""
    rows = []
    idw = max((len(r.case.id) for r in results), default=0)
    for r in results:
        head = f"{r.outcome.verdict.upper():12s} {r.case.id:{idw}s} §{r.case.section}"
        if width is not None and len(head) > width:  # no column padding on a narrow screen
            head = f"{r.outcome.verdict.upper()} {r.case.id} §{r.case.section}"
        line = f"{head}  {r.outcome.evidence}"
        if width is None or len(line) <= width:
            rows.append(line)
        else:  # a narrow terminal: the case on its line, its evidence folded below it
            rows.append(head)
            rows.append(textwrap.fill(r.outcome.evidence, width=max(width, 40),
                                      initial_indent=" " * 4, subsequent_indent=" " * 4,
                                      break_long_words=False, break_on_hyphens=False))
    s = summary(results)
    rows.append(" ".join(f"{v} {s[v]}" for v in VERDICTS))
    return "\n".join(rows)


def listing(cases: Sequence[Case]) -> str:
    rows = [f"{'ID':42s} {'DUT':9s} {'SECTION':10s} {'REQUIREMENT':24s} {'DECISION':9s} TITLE"]
    for c in cases:
        rows.append(f"{c.id:42s} {'/'.join(c.duts):9s} §{c.section:9s} "
                    f"{(c.requirement or '-'):24s} {(c.decision or '-'):9s} {c.title}")
    return "\n".join(rows)


def junit(results: Sequence[Result], suite: str) -> bytes:
    s = summary(results)
    root = ET.Element("testsuites")
    ts = ET.SubElement(root, "testsuite", name=suite, tests=str(len(results)),
                       failures=str(s["fail"]), skipped=str(s["skip"] + s["inconclusive"]),
                       errors="0")
    for r in results:
        c = r.case
        tc = ET.SubElement(ts, "testcase", classname=f"{suite}.{c.group}", name=c.id)
        props = ET.SubElement(tc, "properties")
        for k, v in (("title", c.title), ("section", c.section),
                     ("requirement", c.requirement or ""), ("decision", c.decision or "")):
            ET.SubElement(props, "property", name=k, value=v)
        v = r.outcome.verdict
        if v == "fail":
            ET.SubElement(tc, "failure", message=r.outcome.evidence[:200]).text = \
                r.outcome.evidence
        elif v in ("skip", "inconclusive"):
            ET.SubElement(tc, "skipped", message=f"{v}: {r.outcome.evidence}"[:400])
        else:
            ET.SubElement(tc, "system-out").text = r.outcome.evidence
    return bytes(ET.tostring(root, encoding="utf-8", xml_declaration=True))


def markdown(results: Sequence[Result], title: str) -> str:
    s = summary(results)
    out = [f"# {title}", "", " · ".join(f"**{v}** {s[v]}" for v in VERDICTS), "",
           "| verdict | case | § | requirement | decision | title | evidence |",
           "|---|---|---|---|---|---|---|"]
    for r in results:
        c = r.case
        cells = [r.outcome.verdict, c.id, c.section, c.requirement or "", c.decision or "",
                 c.title, r.outcome.evidence]
        out.append("| " + " | ".join(x.replace("|", "\\|") for x in cells) + " |")
    return "\n".join(out) + "\n"


def html_report(results: Sequence[Result], title: str) -> str:
    s = summary(results)
    colour = {"pass": "#d4f4d4", "fail": "#f8d0d0", "skip": "#eeeeee",
              "inconclusive": "#fff3c4"}
    rows = []
    for r in results:
        c = r.case
        cells = [r.outcome.verdict, c.id, c.section, c.requirement or "", c.decision or "",
                 c.title, r.outcome.evidence]
        tds = "".join(f"<td>{html.escape(x)}</td>" for x in cells)
        rows.append(f'<tr style="background:{colour[r.outcome.verdict]}">{tds}</tr>')
    head = "".join(f"<th>{h}</th>" for h in ("verdict", "case", "§", "requirement",
                                              "decision", "title", "evidence"))
    counts = " · ".join(f"{v} {s[v]}" for v in VERDICTS)
    return (f"<!doctype html><meta charset=utf-8><title>{html.escape(title)}</title>"
            f"<h1>{html.escape(title)}</h1><p>{counts}</p>"
            f"<table border=1 cellpadding=4 style='border-collapse:collapse'>"
            f"<tr>{head}</tr>{''.join(rows)}</table>\n")


def write(path: str, data: str | bytes) -> None:
    try:
        p = Path(path)
        if isinstance(data, bytes):
            p.write_bytes(data)
        else:
            p.write_text(data, encoding="utf-8")
    except OSError as exc:
        raise EyeqError(f"cannot write {path}: {exc}") from None


def write_report(path: str, results: Sequence[Result], title: str) -> None:
    if path.endswith(".md"):
        write(path, markdown(results, title))
    elif path.endswith((".html", ".htm")):
        write(path, html_report(results, title))
    else:
        raise UsageError(f"--report {path}: use a .md or .html file name")
