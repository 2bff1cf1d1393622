"""The load gauge of a real-time run: our own scheduling, measured in the same run, tells a
timing verdict the implementation under test earned from one a loaded machine made.

A real-time session's loop (:meth:`Session.wait`) should come round every ``SLICE``; whenever
it comes round later than ``SLICE + STALL_MIN`` we record a stall (start, end) in the trace. A
stall of ours shifts the receive times of everything that arrived during it (they bunch), delays
our ACKs past the peer's ackTimeout (§6: a frame not ACKed in 10 ms is lost, L7, so its message
and its counters go missing), and tells that the machine, which the peer shares when it runs
beside us, was short of CPU.

Each case declares its rule (``Case.rule`` in the cases table). A *content* rule (counters,
lengths, CRCs, tags, padding, order) is never excused: no stall of ours makes a counter repeat
or a CRC wrong. (Where a stall of ours can lose a message, by delaying our ACK past the peer's
ackTimeout, the counter judges leave the pairs around our stalls unjudged, as they leave those
around our injected faults: judges.app.segments.)

A *timing* judge that fails names each violating measurement: its time span and by how much it
missed its limit (``Outcome.spans``: a late ACK, a period outside its tolerance, a mean rate
off over the whole run, a late MESP reply, a retry or a read that came late). In real time such
a ``fail`` becomes ``inconclusive`` only if every violation is overlapped by stalls of ours at
least as long as its excess; otherwise it stays a ``fail`` and says which violation no stall
explains. A stall thus excuses only the measurements it overlaps, and only by its size. A
timing fail that names no measurement is not excused either. A ``pass`` of a timing case keeps
its verdict and states our worst stall. In virtual time nothing changes.
"""

from __future__ import annotations

from dataclasses import replace

from eyeq_spi.conformance.judges.verdict import Outcome, Span, at, unsure
from eyeq_spi.conformance.model import TIMING, Case
from eyeq_spi.conformance.trace import Trace


def stalls_of(traces: list[Trace]) -> list[tuple[float, float]]:
    return [s for tr in traces for s in tr.stalls]


# A fail our own stalls do not explain: the delay arose in the implementation under test or on
# its way to us. Where that runs (a process on this machine, a device behind a bridge) the suite
# cannot see, so it says no more than that.
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
    total = 0.0
    for stall_start, stall_end in stalls:
        if stall_start <= t1 and stall_end >= t0 - (stall_end - stall_start):
            total += stall_end - stall_start
    return total


def temper(case: Case, outcome: Outcome, traces: list[Trace]) -> Outcome:
    """A real-time verdict of a timing case, weighed against our own stalls in the same run. A
    fail is excused only if each of its violating measurements (``Outcome.spans``) is
    overlapped by stalls of ours at least as long as its excess: an 8 ms stall cannot explain
    a mean rate 40 % off, nor a late ACK half a second later. Content cases are returned as
    they are."""
    if not traces or not all(tr.realtime for tr in traces):
        return outcome
    if case.rule != TIMING or outcome.verdict not in ("pass", "fail"):
        return outcome
    stalls = stalls_of(traces)
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
