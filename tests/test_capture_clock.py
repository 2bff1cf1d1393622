"""A capture says which clock its timestamps were read from, and a real-time run's timestamps
are the clock's readings, not the schedule's (docs/captures.md)."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import pytest

from eyeq_spi.capture.pcapng_io import CaptureWriter, recorded_clock
from eyeq_spi.cli import main
from eyeq_spi.errors import OutputError


def _demo(tmp_path: Path, capsys: pytest.CaptureFixture[str], *extra: str
          ) -> tuple[str, list[float], dict[str, float]]:
    """``demo --capture`` then ``dissect --stats`` and ``--json`` of it: the stats' first line,
    the times of the obstacle messages and the demo summary's ACK latencies."""
    path = str(tmp_path / "run.pcapng")
    assert main(["demo", "--duration", "1.5", "--capture", path, "--json", *extra]) == 0
    with open(path, "rb") as fh:
        head = fh.read(512)
    acks = json.loads(capsys.readouterr().out)["ack_latency_ms"]
    main(["dissect", path, "--stats"])
    first = capsys.readouterr().out.splitlines()[0]
    main(["dissect", path, "--json"])
    times = [r["time"] for r in map(json.loads, capsys.readouterr().out.splitlines())
             if r.get("name") == "EYEQ_VIS_OBSTACLES_MSG"]
    return first + " " + str(recorded_clock(head)), times, acks


def test_a_virtual_time_capture_says_virtual(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    said, times, _ = _demo(tmp_path, capsys, "--virtual-time")
    assert said.endswith("clock: virtual virtual"), said
    periods = {round(b - a, 6) for a, b in itertools.pairwise(times)}
    assert len(times) > 10 and max(periods) - min(periods) < 2e-6  # the schedule, exactly


@pytest.mark.realtime
def test_a_real_time_capture_reads_the_clock(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    said, times, acks = _demo(tmp_path, capsys)
    assert said.endswith("clock: monotonic monotonic"), said
    assert acks["n"] > 10 and acks["max"] > acks["p50"], acks  # the clock's, not one value
    periods = [b - a for a, b in itertools.pairwise(times)]
    assert len(periods) > 10 and len({round(p, 6) for p in periods}) > 3, periods
    assert abs(sum(periods) / len(periods) - 1 / 18) < 0.01  # and keeps up with the clock


def test_a_capture_without_the_comment_does_not_say(tmp_path: Path) -> None:
    path = tmp_path / "other.pcapng"
    with CaptureWriter(path, idle_flush=False) as writer:
        writer.write("h2e", 0.0, bytes(128))
    assert recorded_clock(path.read_bytes()) is None
    with pytest.raises(OutputError, match="unknown capture clock"):
        CaptureWriter(tmp_path / "x.pcapng", time_base="sundial", idle_flush=False)
