"""The load gauge of real-time conformance runs (conformance/load.py): each case declares in the
cases table whether its rule is one of timing or of content. A content fail is never excused by
a stall of ours; a timing fail becomes inconclusive only when every violating measurement is
overlapped by stalls of ours at least as long as its excess, so a stall elsewhere in the run
excuses nothing; virtual time is untouched. Hand-made traces, injected stall records and
outcomes in virtual time, plus the stall recorder of the session."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.conformance.cases import all_cases, cases_for
from eyeq_spi.conformance.judges.app import dasp_counter
from eyeq_spi.conformance.judges.verdict import Context, Outcome, bad, ok
from eyeq_spi.conformance.load import excused, temper
from eyeq_spi.conformance.model import CONTENT, STALL_MIN, TIMING, Case
from eyeq_spi.conformance.play.session import SLICE, Session
from eyeq_spi.conformance.trace import Trace
from eyeq_spi.link.frame import FrameCodec
from eyeq_spi.transport.segment import segment

RATE = "DASP-RATE-APP-EYEQ_VIS_OBSTACLES_MSG"
STUCK = "data ID 0xA0: counter 0 (#74) then 0 (#90, t=0.4209s), expected +1 (D1)"


def _case(case_id: str, dut: str = "eyeq") -> Case:
    return next(c for c in cases_for(dut) if c.id == case_id)


def _trace(stalls: list[tuple[float, float]], *, realtime: bool = True) -> Trace:
    tr = Trace("eyeq", realtime=realtime)
    tr.stalls = list(stalls)
    return tr


def _temper(case_id: str, out: Outcome, stalls: list[tuple[float, float]], *,
            realtime: bool = True) -> Outcome:
    return temper(_case(case_id), out, [_trace(stalls, realtime=realtime)])


def test_every_case_declares_its_rule() -> None:
    cases = all_cases()
    assert {c.rule for c in cases} == {TIMING, CONTENT}
    timing = {c.id for c in cases if c.rule == TIMING}
    assert {"LINK-ACK", "LINK-WINDOW", "LINK-TXTIMEOUT", "LINK-GAP", "MESP-DEADLINE",
            "DIAG-RATE", "HOST-RETRY", "HOST-FATAL22", RATE} <= timing
    # counters, lengths, CRCs, tags, padding, order
    for cid in ("DASP-COUNTER", "DASP-E2E", "DASP-LENGTH", "LINK-CRC", "LINK-PAD", "MESP-TAG",
                "MESP-REQTAG", "TP-FORMAT", "TP-ABORT"):
        assert cid not in timing, cid


def test_a_content_fail_and_an_unrelated_stall_stay_a_fail() -> None:
    """DASP-COUNTER against an EyeQ whose counter never increments, with a stall of ours ten
    seconds later: still a fail, and the evidence is the judge's alone."""
    out = _temper("DASP-COUNTER", bad(STUCK), [(10.7632, 10.7746)])
    assert out == bad(STUCK)


def test_no_content_rule_is_ever_excused() -> None:
    whole = [(0.0, 100.0)]  # a stall over the whole run
    for c in all_cases():
        if c.rule == CONTENT:
            out = bad("x", [(1.0, 2.0, 0.001)])
            assert temper(c, out, [_trace(whole)]) == out, c.id


def test_a_timing_fail_overlapped_by_a_long_enough_stall_is_inconclusive() -> None:
    late = bad("period 98 ms at t=1.0s", [(0.902, 1.0, 0.030)])  # 30 ms beyond the limit
    out = _temper(RATE, late, [(0.95, 0.95 + 0.031)])
    assert out.verdict == "inconclusive"
    assert "period 98 ms" in out.evidence and "our own loop stalled 1 times" in out.evidence


def test_a_timing_fail_with_a_stall_elsewhere_stays_a_fail() -> None:
    late = bad("period 98 ms at t=1.0s", [(0.902, 1.0, 0.030)])
    out = _temper(RATE, late, [(10.0, 10.5)])  # half a second of stall, ten seconds later
    assert out.verdict == "fail"
    assert "1 of 1 violations not explained by our stalls" in out.evidence
    assert "not caused by our side" in out.evidence
    # overlapping, but shorter than the excess
    assert _temper(RATE, late, [(0.95, 0.96)]).verdict == "fail"


def test_a_timing_fail_naming_no_measurement_stays_a_fail() -> None:
    out = _temper("LINK-ACK", bad("late"), [(0.0, 100.0)])
    assert out.verdict == "fail" and "named no measurement" in out.evidence


def test_virtual_time_and_other_verdicts_are_untouched() -> None:
    stall = [(0.0, 1.0)]
    out = bad("period 98 ms", [(0.0, 1.0, 0.001)])
    assert _temper(RATE, out, stall, realtime=False) == out
    passed = _temper(RATE, ok("fine"), stall)
    assert passed.verdict == "pass" and "our own loop stalled" in passed.evidence  # stated
    assert _temper("DASP-LENGTH", ok("fine"), stall) == ok("fine")  # content: as judged


@given(st.lists(st.tuples(st.floats(0.0, 5.0), st.floats(0.0, 0.05)), max_size=8),
       st.lists(st.tuples(st.floats(0.0, 5.0), st.floats(0.0, 0.1), st.floats(0.0, 0.05)),
                min_size=1, max_size=5))
def test_excused_exactly_when_every_violation_is_covered(
        stalls: list[tuple[float, float]], spans: list[tuple[float, float, float]]) -> None:
    stalls = [(a, a + d) for a, d in stalls]
    spans = [(a, a + d, x) for a, d, x in spans]
    out = _temper(RATE, bad("late", spans), stalls)
    covered = all(excused(sp, stalls) >= sp[2] for sp in spans)
    assert out.verdict == ("inconclusive" if covered else "fail")


# -- the counters judge: a content rule, judged between our stalls -----------------------------
def _dasp_trace(counters: list[int], stalls: list[tuple[float, float]]) -> Trace:
    """A host under test sending HOST_VEH_STATE_MSG every 15 ms with these DASP counters."""
    tr = Trace("host", realtime=True)
    tr.stalls = list(stalls)
    codec, frames = MessageCodec(), FrameCodec()
    values = codec.layout(codec.message("HOST_VEH_STATE_MSG")).zero_values()
    for k, counter in enumerate(counters):
        msg = codec.encode_dasp("HOST_VEH_STATE_MSG", values, counter)
        [payload] = segment(msg, 0)
        tr.add("h2e", 0.1 + 0.015 * k, frames.data_frame(0, k, payload))
    return tr


def test_a_stuck_counter_fails_beside_a_stall_ten_seconds_later() -> None:
    tr = _dasp_trace([0] * 20, [(10.7632, 10.7746)])
    out = temper(_case("DASP-COUNTER", "host"), dasp_counter(Context("host", True), tr), [tr])
    assert out.verdict == "fail" and "counter 0" in out.evidence, out


def test_a_counter_gap_over_our_stall_is_not_judged() -> None:
    """Our loop stalled while the message between them was sent: our late ACK may have lost
    it (L7), so that pair is not judged; the same gap away from any stall fails."""
    counters = [*range(10), *range(11, 20)]  # one message missing after the 10th (t=0.235 s)
    quiet = _dasp_trace(counters, [])
    assert dasp_counter(Context("host", True), quiet).verdict == "fail"
    stalled = _dasp_trace(counters, [(0.236, 0.25)])
    assert dasp_counter(Context("host", True), stalled).verdict == "pass"


@pytest.mark.realtime
def test_the_session_records_its_own_stalls() -> None:
    class Busy:  # a node that hogs the loop for 30 ms once, as a loaded machine would
        def __init__(self) -> None:
            self.done = False

        def receive_data(self, transfer: bytes, now: float) -> None: ...

        def data_to_send(self, now: float) -> list[bytes]:
            if not self.done and now > 0.02:
                self.done = True
                import time
                time.sleep(0.03)
            return []

        def get_timer(self) -> float | None:
            return None

        def handle_timer(self, now: float) -> None: ...

    from eyeq_spi.phy.memory import memory_pair

    a, _b = memory_pair()
    tr = Trace("eyeq", realtime=True)
    s = Session(tr, Busy(), adapter=a)
    try:
        s.run(0.1)
    finally:
        s.finish()  # as the suite does: the real-time runner gives the collector back
    assert any(e - st_ >= 0.03 for st_, e in tr.stalls), tr.stalls
    assert all(e - st_ > SLICE + STALL_MIN for st_, e in tr.stalls)
