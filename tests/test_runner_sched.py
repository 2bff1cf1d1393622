"""Real-time scheduling of live runs (``eyeq_spi/runner/sched.py``): obtained when allowed,
reported when refused, and given back when the run ends."""

from __future__ import annotations

import os
from typing import Any

import pytest

from eyeq_spi.runner import sched

RESET_ON_FORK = getattr(os, "SCHED_RESET_ON_FORK", 0)


def _fifo_allowed() -> bool:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except (OSError, AttributeError):
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


@pytest.mark.skipif(not _fifo_allowed(), reason="SCHED_FIFO is refused to this process (not "
                    "root, no CAP_SYS_NICE or RLIMIT_RTPRIO)")
def test_a_live_run_is_real_time_and_gives_it_back() -> None:
    before = os.sched_getscheduler(0)
    with sched.realtime(7) as got:
        assert got == "SCHED_FIFO 7"
        assert os.sched_getscheduler(0) & ~RESET_ON_FORK == os.SCHED_FIFO
        assert os.sched_getparam(0).sched_priority == 7
    assert os.sched_getscheduler(0) == before  # a test or notebook is not left real-time


def test_priority_zero_leaves_scheduling_alone() -> None:
    before = os.sched_getscheduler(0)
    with sched.realtime(0) as got:
        assert got.startswith("SCHED_OTHER") and "not requested" in got
        assert os.sched_getscheduler(0) == before


def test_refused_real_time_is_reported_never_raised(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*_: Any) -> None:
        raise PermissionError(1, "Operation not permitted")

    calls: list[int] = []

    def nice(inc: int) -> int:
        calls.append(inc)
        if inc < 0:
            raise PermissionError(1, "Operation not permitted")
        return 0

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    monkeypatch.setattr(os, "nice", nice)
    got = sched.request_realtime(10)
    assert got == "SCHED_OTHER (SCHED_FIFO refused: Operation not permitted)"
    assert -10 in calls


def test_the_nice_fallback_is_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*_: Any) -> None:
        raise PermissionError(1, "Operation not permitted")

    level = [0]

    def nice(inc: int) -> int:
        level[0] += inc
        return level[0]

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    monkeypatch.setattr(os, "nice", nice)
    assert sched.request_realtime(10) == "nice -10 (SCHED_FIFO refused: Operation not permitted)"
