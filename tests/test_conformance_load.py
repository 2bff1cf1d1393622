"""The load gauge of real-time conformance runs (conformance/load.py): a timing fail becomes
inconclusive only when our own loop stalled at least the case's tolerance in the same run; a
quiet run keeps the fail; structural cases and E2E CRC errors are never excused; virtual time
is untouched. Hand-made traces and outcomes, plus the stall recorder of the session."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eyeq_spi.conformance.cases import cases_for
from eyeq_spi.conformance.judges.verdict import Outcome, bad, ok
from eyeq_spi.conformance.load import rule_for, temper
from eyeq_spi.conformance.model import STALL_MIN, Case
from eyeq_spi.conformance.play.session import SLICE, Session
from eyeq_spi.conformance.trace import Trace

RATE = "DASP-RATE-APP-EYEQ_VIS_OBSTACLES_MSG"


def _case(case_id: str, dut: str = "eyeq") -> Case:
    return next(c for c in cases_for(dut) if c.id == case_id)


def _trace(stalls: list[tuple[float, float]], *, realtime: bool = True) -> Trace:
    tr = Trace("eyeq", realtime=realtime)
    tr.stalls = list(stalls)
    return tr


def _temper(case_id: str, out: Outcome, stalls: list[tuple[float, float]], *,
            realtime: bool = True) -> Outcome:
    return temper(_case(case_id), out, [_trace(stalls, realtime=realtime)], dut="eyeq", sw=None)


def test_timing_fail_with_a_long_stall_is_inconclusive_with_both_evidences() -> None:
    out = _temper(RATE, bad("period 98 ms at t=1.0s"), [(0.5, 0.5 + 0.030)])
    assert out.verdict == "inconclusive"
    assert "period 98 ms" in out.evidence and "our own loop stalled 1 times" in out.evidence
    assert "30.0 ms" in out.evidence


def test_quiet_run_keeps_the_fail() -> None:
    tol, _ = rule_for(_case(RATE), "eyeq", None)  # type: ignore[misc]
    out = _temper(RATE, bad("period 98 ms"), [(0.5, 0.5 + tol * 0.9)])
    assert out.verdict == "fail" and "not caused by our side" in out.evidence
    assert _temper(RATE, bad("x"), []).verdict == "fail"


def test_structural_cases_and_crc_errors_are_never_excused() -> None:
    stall = [(0.0, 1.0)]  # a whole second
    assert _temper("LINK-CRC", bad("bad CRC"), stall).verdict == "fail"
    assert _temper("TP-FORMAT", bad("interleaved"), stall).verdict == "fail"
    crc = bad("HOST_VEH_STATE_MSG #3: E2E CRC mismatch in x: crc_16=0x1, computed 0x2 (D5)")
    assert _temper("DASP-E2E", crc, stall).verdict == "fail"
    jump = bad("x.y: rollingFrameCount 3 (#1) then 5 (#9, t=1s), expected +1 (D5)")
    assert _temper("DASP-E2E", jump, stall).verdict == "inconclusive"


def test_virtual_time_and_other_verdicts_are_untouched() -> None:
    stall = [(0.0, 1.0)]
    out = bad("period 98 ms")
    assert _temper(RATE, out, stall, realtime=False) == out
    passed = _temper(RATE, ok("fine"), stall)
    assert passed.verdict == "pass" and "our own loop stalled" in passed.evidence  # stated


@given(st.lists(st.floats(min_value=0.0, max_value=0.2), max_size=20),
       st.sampled_from(["LINK-ACK", "LINK-WINDOW", "DASP-COUNTER", "MESP-DEADLINE", RATE,
                        "DIAG-RATE", "LINK-GAP"]))
def test_excused_exactly_when_a_stall_reaches_the_tolerance(lengths: list[float],
                                                            case_id: str) -> None:
    rule = rule_for(_case(case_id), "eyeq", None)
    assert rule is not None
    stalls = [(float(i), i + d) for i, d in enumerate(lengths)]
    out = _temper(case_id, bad("late"), stalls)
    excused = any(e - s >= rule[0] for s, e in stalls)
    assert out.verdict == ("inconclusive" if excused else "fail")


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
