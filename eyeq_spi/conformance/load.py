"""The load gauge of a real-time run: our own scheduling, measured in the same run, tells a
timing verdict the implementation under test earned from one a loaded machine made.

A real-time session's loop (:meth:`Session.wait`) should come round every ``SLICE``; whenever
it comes round later than ``SLICE + STALL_MIN`` we record a stall (start, end) in the trace. A
stall of ours shifts the receive times of everything that arrived during it (they bunch), delays
our ACKs past the peer's ackTimeout (§6: a frame not ACKed in 10 ms is lost, L7, so its message
and its counters go missing), and tells that the machine, which the peer shares when it runs
beside us, was short of CPU.

A timing judge that fails names each violating measurement: its time span and by how much it
missed its limit (``Outcome.spans``: a late ACK, a period outside its tolerance, a mean rate
off over the whole run, a late MESP reply). In real time such a ``fail`` becomes
``inconclusive`` only if every violation is overlapped by stalls of ours at least as long as its
excess; otherwise it stays a ``fail`` and says which violation no stall explains. A stall thus
excuses only the measurements it overlaps, and only by its size.

A judge that names no spans falls back to its case's tolerance: the shortest time its verdict
turns on (10 ms ackTimeout for lost messages, for instance); a fail in a run where one of our
stalls reached it becomes ``inconclusive`` with both pieces of evidence. A ``pass`` keeps its
verdict and states our worst stall. In virtual time nothing changes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from eyeq_spi.catalog.link import link_spec
from eyeq_spi.catalog.messages import catalog
from eyeq_spi.conformance.judges.verdict import Outcome, Span, at, unsure
from eyeq_spi.conformance.model import Case
from eyeq_spi.conformance.trace import Trace

_TIMING = link_spec()["timing"]
ACK_TIMEOUT = float(_TIMING["ackTimeout"])
GAP_SPAN = 50  # LINK-GAP judges 50-frame means (judges.link.link_gap)

_Rule = tuple[float, Callable[[str], bool]]


def _any(evidence: str) -> bool:
    return True


def _counter_only(evidence: str) -> bool:
    # DASP-E2E: a rollingFrameCount jump follows a lost message; a CRC mismatch never does
    return "rollingFrameCount" in evidence or "counter" in evidence


def _rules(dut: str, sw: str | None) -> dict[str, _Rule]:
    gap = float(_TIMING["frameFlowControl"][dut])
    rules: dict[str, _Rule] = {
        "LINK-GAP": (GAP_SPAN * gap / 2, _any),  # half the span's gap compressed into a burst
        "LINK-TXTIMEOUT": (ACK_TIMEOUT, _any),
        "LINK-ACK": (ACK_TIMEOUT, _any),
        "LINK-WINDOW": (ACK_TIMEOUT, _any),  # "unacknowledged" counts frames younger than 10 ms
        "MESP-DEADLINE": (0.1, _any),
        "DIAG-RATE": (0.025, _any),  # 0x41's tolerance, -25/+50 ms (§7.1.5)
        "DASP-COUNTER": (ACK_TIMEOUT, _any),
        "DASP-E2E": (ACK_TIMEOUT, _counter_only),
        "TP-ABORT": (ACK_TIMEOUT, _any),  # our own frames 25 ms apart by accident
    }
    cat = catalog()
    key = cat.sw(sw)
    for m in cat.messages:
        if m.protocol != "DASP" or not m.exists_in(key) or m.rate_hz is None:
            continue
        lo, hi = m.tolerance_ms or (0.0, 0.0)
        tol = max(min(abs(lo), abs(hi)), 1.0) / 1e3
        for mode in m.modes:
            rules[f"DASP-RATE-{mode}-{m.name}"] = (tol, _any)
    return rules


_CACHE: dict[tuple[str, str | None], dict[str, _Rule]] = {}


def rule_for(case: Case, dut: str, sw: str | None) -> _Rule | None:
    key = (dut, sw)
    if key not in _CACHE:
        _CACHE[key] = _rules(dut, sw)
    return _CACHE[key].get(case.id)


def stalls_of(traces: list[Trace]) -> list[tuple[float, float]]:
    return [s for tr in traces for s in tr.stalls]


# A fail our own stalls do not explain: the delay arose in the implementation under test or on
# its way to us. Where that runs (a process on this machine, a device behind a bridge) the suite
# cannot see, so it says no more than that.
NOT_OURS = "not caused by our side: the implementation under test or its link"


def describe(stalls: list[tuple[float, float]], tol: float) -> str:
    if not stalls:
        return "our own loop never stalled in this run"
    worst = max(stalls, key=lambda s: s[1] - s[0])
    over = sum(1 for a, b in stalls if b - a >= tol)
    return (f"our own loop stalled {len(stalls)} times, {over} of them >= {1e3 * tol:.1f} ms, "
            f"worst {1e3 * (worst[1] - worst[0]):.1f} ms at {at(worst[0])}")


def excused(span: Span, stalls: list[tuple[float, float]]) -> float:
    """Seconds of our own stalls that can explain one violating measurement: the stalls that
    overlap it in time. A stall ending just before the measurement starts counts too (the
    messages that arrived during it were recorded late, so the next period begins late)."""
    t0, t1, _ = span
    total = 0.0
    for a, b in stalls:
        if a <= t1 and b >= t0 - (b - a):
            total += b - a
    return total


def temper(case: Case, outcome: Outcome, traces: list[Trace], *, dut: str,
           sw: str | None) -> Outcome:
    """A real-time timing verdict, weighed against our own stalls in the same run. A fail that
    names its violating measurements (``Outcome.spans``) is excused only if every one of them
    is overlapped by stalls of ours at least as long as its excess: an 8 ms stall cannot
    explain a mean rate 40 % off, nor a late ACK half a second later."""
    if not traces or not all(tr.realtime for tr in traces):
        return outcome
    rule = rule_for(case, dut, sw)
    if rule is None or outcome.verdict not in ("pass", "fail"):
        return outcome
    tol, applies = rule
    stalls = stalls_of(traces)
    gauge = describe(stalls, tol)
    if outcome.verdict == "pass":
        return replace(outcome, evidence=f"{outcome.evidence} ({gauge})")
    if outcome.spans:
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
    if not applies(outcome.evidence) or not any(b - a >= tol for a, b in stalls):
        return replace(outcome, evidence=f"{outcome.evidence} ({gauge}: {NOT_OURS})")
    return unsure(f"{outcome.evidence}; but {gauge}: the machine was loaded, so this timing "
                  "cannot be blamed on the implementation under test (rerun on a quiet "
                  "machine)")
