"""Bounded live soak: host and simulated EyeQ as two processes in real time at full load over TCP
and over a pty, 20 s each in CI and 5 s in a local run (``EYEQ_SOAK_S`` changes it).

What a test can hold on any machine is the accounting, not the schedule: Running Vision reached
and held on both sides, losses a tiny fraction, and every loss one side reports explained by a
send failure of the other (a frame not ACKed within the 10 ms ackTimeout, L7), so that nothing
is lost silently and nothing accepted is corrupted. Zero loss itself depends on the machine: both
processes take SCHED_FIFO (``--rt-priority``, ``eyeq_spi/runner/sched.py``), but the kernel
delivers loopback TCP in softirq context and a pty write from a worker thread, both at ordinary
priority, and other CPU-bound work can delay them past the ackTimeout (over TCP about one run in
ten lost one frame on a 2-core machine at load 4; over a pty more). The zero-loss figure is the
benchmark's: ``python3 tools/soak_live.py --duration 600`` (figures in docs/emulator.md)."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import soak_live


def _seconds() -> float:
    """How long each soak runs: ``EYEQ_SOAK_S``, else 20 s in CI and 5 s locally (bring-up and
    several seconds at full load either way)."""
    return float(os.environ.get("EYEQ_SOAK_S") or (20 if os.environ.get("CI") else 5))


def _fifo_allowed() -> bool:
    """Whether this process may take SCHED_FIFO (then it gives it back)."""
    if not hasattr(os, "sched_setscheduler"):
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except OSError:
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


def every_loss_accounted(run: dict[str, Any]) -> None:
    """Both sides held Running Vision; each side's send failures are under 1 % of its
    frames; each side's summary says ``ok`` exactly when it lost nothing and names the loss
    otherwise; and what a side lost on receive is explained by the other side's send failures:
    none of them, no loss at all; otherwise at most one transfer abort and one DASP counter gap
    per failure, and E2E rejections only after a gap (D5: the next structure's rolling counter
    jumps)."""
    for side, peer in (("host", "sim"), ("sim", "host")):
        mine, theirs = run[side], run[peer]
        # the whole figures as text (a dict in the message would be cut to 240 characters):
        # a loss here is rare and must be readable from the CI log alone
        said = f"{side}: {json.dumps(mine, default=str)}; {peer}: {json.dumps(theirs, default=str)}"
        assert mine["state"] in ("RUNNING_VISION", "0x02"), said
        # a regression in the ACK path loses far more; a pty beside four busy processes lost
        # 24 frames in 21,546 (0.11 %) with every one of them accounted for
        assert mine["send_failures"] <= max(5, mine["ack_latency_ms"]["n"] // 100), said
        assert mine["ok"] == soak_live.lossless(mine), said
        assert (mine["problem"] is None) == mine["ok"], said
        failed = theirs["send_failures"]
        aborts = sum(mine["transport_aborts"].values())
        if failed == 0:
            # (a stale stream is silence, not loss: a delivery the kernel held back makes one)
            assert not (mine["e2e_errors"] or mine["dasp_counter_gaps"] or aborts), said
        assert aborts <= failed and mine["dasp_counter_gaps"] <= failed, said
        assert mine["e2e_errors"] == 0 or mine["dasp_counter_gaps"] > 0, said
    assert run["host_problem"] is None or "Running Vision" not in run["host_problem"], run


@pytest.mark.realtime
@pytest.mark.skipif(not _fifo_allowed(),
                    reason="SCHED_FIFO is refused here (not root, no CAP_SYS_NICE or "
                    "RLIMIT_RTPRIO): without it the kernel may leave a woken process waiting "
                    "past the 10 ms ackTimeout on any busy machine, and the losses are not "
                    "the rare event this test bounds")
def test_live_run_over_tcp_accounts_for_every_loss() -> None:
    run = soak_live.soak(_seconds(), "tcp")
    for side in ("host", "sim"):
        assert run[side]["scheduling"].startswith("SCHED_FIFO"), run[side]["scheduling"]
    every_loss_accounted(run)


@pytest.mark.realtime
def test_live_run_over_a_pty_accounts_for_every_loss() -> None:
    every_loss_accounted(soak_live.soak(_seconds(), "pty"))


def _side(send_failures: int = 0, gaps: int = 0, e2e: int = 0,
          aborts: dict[str, int] | None = None) -> dict[str, Any]:
    side = {"state": "RUNNING_VISION", "send_failures": send_failures,
            "ack_latency_ms": {"n": 20000}, "e2e_errors": e2e, "dasp_counter_gaps": gaps,
            "transport_aborts": aborts or {}, "stale_streams": [], "mesp_timeouts": 0}
    side["ok"] = soak_live.lossless(side)
    side["problem"] = None if side["ok"] else "lost"
    return side


def test_the_accounting_tells_an_explained_loss_from_a_silent_one() -> None:
    """The figures of a real TCP run that lost one frame (the sim's frame not ACKed in time; the
    host's transfer aborted, one DASP gap, the next obstacles message's 16 structures rejected)
    pass; the same host figures without the sim's failure, and a rejection without a gap, fail."""
    explained = {"host": _side(gaps=1, e2e=16, aborts={"interleaved": 1}),
                 "sim": _side(send_failures=1), "host_problem": None}
    every_loss_accounted(explained)
    silent = {**explained, "sim": _side()}
    with pytest.raises(AssertionError):
        every_loss_accounted(silent)
    corrupt = {"host": _side(e2e=16), "sim": _side(send_failures=1), "host_problem": None}
    with pytest.raises(AssertionError):
        every_loss_accounted(corrupt)
