"""Bounded live soak: host and simulated EyeQ as two processes in real time at full load over TCP
and over a pty, 20 s each in CI and 8 s in a local run (``EYEQ_SOAK_S`` changes it), asserting
zero losses on both sides. Both processes take SCHED_FIFO by default (``--rt-priority``,
``eyeq_spi/runner/sched.py``), which is what keeps their ACKs inside the 10 ms ackTimeout while
other work loads the machine. The 10-minute version is ``python3 tools/soak_live.py --duration
600`` (figures in docs/emulator.md)."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import soak_live


def _seconds() -> float:
    """How long each soak runs: ``EYEQ_SOAK_S``, else 20 s in CI and 8 s locally (bring-up and
    several seconds at full load either way)."""
    return float(os.environ.get("EYEQ_SOAK_S") or (20 if os.environ.get("CI") else 8))


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


@pytest.mark.realtime
@pytest.mark.skipif(not _fifo_allowed(),
                    reason="SCHED_FIFO is refused here (not root, no CAP_SYS_NICE or "
                    "RLIMIT_RTPRIO): without it the kernel may leave a woken process waiting "
                    "past the 10 ms ackTimeout on a busy machine, so zero loss cannot be asserted")
def test_live_run_over_tcp_loses_nothing() -> None:
    r = soak_live.soak(_seconds(), "tcp")
    for side in ("host", "sim"):
        assert r[side]["scheduling"].startswith("SCHED_FIFO"), r[side]["scheduling"]
        assert r[side]["state"] in ("RUNNING_VISION", "0x02"), r
        # the whole figures as text (a dict in the message would be cut to 240 characters):
        # a loss here is rare and must be readable from the CI log alone
        assert soak_live.lossless(r[side]), f"{side}: {json.dumps(r[side], default=str)}"


@pytest.mark.realtime
def test_live_run_over_a_pty_holds_vision_and_reports_every_loss() -> None:
    """Over a pty the kernel moves each write to the reader from a worker thread at ordinary
    priority, which other CPU-bound work can delay past the 10 ms ackTimeout whatever our
    priority (600 s lost nothing on a quiet machine, 23 frames of 700,000 at load 0.5-3.6;
    README, Live runs), and CI machines are not always quiet. So this run asserts what must hold
    anyway: Running Vision reached and held on both sides, losses a tiny fraction, and every loss
    counted and named in `problem` (summaries tell the truth)."""
    r = soak_live.soak(_seconds(), "pty")
    for side in ("host", "sim"):
        x = r[side]
        assert x["state"] in ("RUNNING_VISION", "0x02"), r
        frames = x["ack_latency_ms"]["n"]
        assert x["send_failures"] <= max(5, frames // 1000), (side, x)
        assert x["ok"] == soak_live.lossless(x), (side, x)
        assert (x["problem"] is None) == x["ok"], (side, x)
    assert r["host_problem"] is None or "Running Vision" not in r["host_problem"], r
