"""The load gauge of a real-time run: a timing fail is excused only by stalls of our own loop
that overlap each of its violating measurements by at least its excess; a content fail never
is (docs/conformance.md, "Real time on a loaded machine")."""

from __future__ import annotations

from dataclasses import replace

from eyeq_spi.conformance.judges.verdict import Outcome, Span, at, unsure
from eyeq_spi.conformance.model import TIMING, Case
from eyeq_spi.conformance.trace import Trace

# a fail our own stalls do not explain: the suite cannot see where the DUT or its link runs
NOT_OURS = "not caused by our side: the implementation under test or its link"


def describe(stalls: list[tuple[float, float]]) -> str:
    if not stalls:
        return "our own loop never stalled in this run"
    worst = max(stalls, key=lambda s: s[1] - s[0])
    return (f"our own loop stalled {len(stalls)} times, worst "
            f"{1e3 * (worst[1] - worst[0]):.1f} ms at {at(worst[0])}")


def excused(span: Span, stalls: list[tuple[float, float]]) -> float:
    """Seconds of our own stalls that can explain one violating measurement: the stalls that
    overlap it in time. A stall ending just before the measurement starts counts too (the
    messages that arrived during it were recorded late, so the next period begins late)."""
    t0, t1, _ = span
    return sum(end - start for start, end in stalls if start <= t1 and end >= t0 - (end - start))


def temper(case: Case, outcome: Outcome, traces: list[Trace]) -> Outcome:
    """A real-time verdict of a timing case, weighed against our own stalls in the same run;
    content cases are returned as they are."""
    if not traces or not all(tr.realtime for tr in traces):
        return outcome
    if case.rule != TIMING or outcome.verdict not in ("pass", "fail"):
        return outcome
    stalls = [stall for tr in traces for stall in tr.stalls]
    gauge = describe(stalls)
    if outcome.verdict == "pass":
        return replace(outcome, evidence=f"{outcome.evidence} ({gauge})")
    if not outcome.spans:
        return replace(outcome, evidence=f"{outcome.evidence} ({gauge}; the judge named no "
                                         f"measurement a stall could explain: {NOT_OURS})")
    unexplained = [sp for sp in outcome.spans if excused(sp, stalls) < sp[2]]
    if unexplained:
        t0, t1, excess = unexplained[0]
        return replace(outcome, evidence=(
            f"{outcome.evidence} ({gauge}; {len(unexplained)} of {len(outcome.spans)} "
            f"violations not explained by our stalls, first {at(t0)}..{at(t1)}: "
            f"{1e3 * excess:.1f} ms beyond the limit, our stalls overlapping it "
            f"{1e3 * excused((t0, t1, excess), stalls):.1f} ms: {NOT_OURS})"))
    return unsure(f"{outcome.evidence}; but each of the {len(outcome.spans)} violations is "
                  f"overlapped by stalls of our own loop at least as long as its excess "
                  f"({gauge}): this timing cannot be blamed on the implementation under "
                  "test (rerun on a quiet machine)")
