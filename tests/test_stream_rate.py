"""One definition of a stream's rate: over its active spans, gaps reported apart."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from eyeq_spi.cli import main
from eyeq_spi.stream_rate import GAP_FACTOR, combined_rate, stream_rate


def test_a_gap_is_not_averaged_into_the_rate() -> None:
    times = [i * 0.015 for i in range(20)] + [1.0 + i * 0.015 for i in range(20)]
    rate = stream_rate(times)
    assert rate.rate_hz == pytest.approx(1 / 0.015)
    assert rate.spans == 2 and len(rate.gaps) == 1
    assert rate.gaps[0].start == pytest.approx(19 * 0.015)


def test_missed_messages_are_a_slower_stream_not_a_gap() -> None:
    times = [i * 0.1 for i in range(10)] + [0.9 + 0.3, 0.9 + 0.4]  # two missed: 3 periods
    rate = stream_rate(times)
    assert not rate.gaps and rate.rate_hz == pytest.approx(11 / 1.3)
    assert GAP_FACTOR == 4.0


def test_too_few_messages_have_no_rate() -> None:
    assert stream_rate([]).rate_hz is None and stream_rate([1.0]).rate_hz is None
    assert combined_rate([stream_rate([0.0, 1.0]), stream_rate([5.0, 5.5, 6.0])]) == \
        pytest.approx(3 / 2.0)


def test_dissect_stats_gives_the_rate_while_the_stream_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A demo's host stops sending HOST_VEH_STATE_MSG while it resets the EyeQ at bring-up."""
    path = str(tmp_path / "d.pcapng")
    assert main(["demo", "--virtual-time", "--duration", "3", "--capture", path]) == 0
    capsys.readouterr()
    main(["dissect", path, "--stats", "--json"])
    stats = json.loads(capsys.readouterr().out.splitlines()[-1])
    veh = stats["messages"]["HOST_VEH_STATE_MSG"]
    assert veh["mean_hz"] == pytest.approx(66.67, abs=0.1) and veh["gaps"] == 1, veh
    assert stats["messages"]["EYEQ_DIAGNOSTIC_MSG"]["mean_hz"] == pytest.approx(37, abs=0.1)
