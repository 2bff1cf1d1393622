"""Bounded live soak (issue 8): host and simulated EyeQ as two processes in real time at full
load over TCP and over a pty, asserting zero losses on both sides. The 10-minute version is
``python3 tools/soak_live.py --duration 600`` (figures in the README)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import soak_live


@pytest.mark.realtime
@pytest.mark.skipif(not os.environ.get("EYEQ_SOAK"),
                    reason="set EYEQ_SOAK=1: the zero-loss bar needs a machine not shared with "
                    "other CPU-bound work (two real-time processes on 2 cores)")
@pytest.mark.parametrize("transport", ["tcp", "pty"])
def test_live_run_loses_nothing(transport: str) -> None:
    r = soak_live.soak(20.0, transport)
    for side in ("host", "sim"):
        assert r[side]["state"] in ("RUNNING_VISION", "0x02"), r
        assert soak_live.lossless(r[side]), (side, r[side])
