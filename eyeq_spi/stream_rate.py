"""The one definition of a stream's rate, for ``dissect --stats``, ``monitor``, ``plot`` and
``conformance`` (docs/dissector.md, "Rates"): a function of the times a stream's messages were
seen, over its active spans only. A period longer than :data:`GAP_FACTOR` median periods is a
gap (an EyeQ reset, a mode switch, a stall), reported apart rather than averaged into the rate;
a stream that misses up to three messages in a row is still running."""

from __future__ import annotations

import itertools
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

GAP_FACTOR = 4.0  # a period over 4x the median period is a gap between two spans


@dataclass(frozen=True)
class Gap:
    """A silence of ``length`` seconds after the message seen at ``start``."""

    start: float
    length: float


@dataclass(frozen=True)
class StreamRate:
    """A stream's rate over its active spans (None with fewer than two messages)."""

    count: int  # messages seen
    steps: int  # periods inside spans
    active_s: float  # total duration of the spans
    median_period_s: float | None
    gaps: tuple[Gap, ...]

    @property
    def rate_hz(self) -> float | None:
        return self.steps / self.active_s if self.steps and self.active_s > 0 else None

    @property
    def spans(self) -> int:
        return len(self.gaps) + 1 if self.count else 0


def stream_rate(times: Sequence[float], gap_factor: float = GAP_FACTOR) -> StreamRate:
    """The rate of a stream whose messages were seen at ``times`` (seconds, rising)."""
    periods = [b - a for a, b in itertools.pairwise(times)]
    if not periods:
        return StreamRate(len(times), 0, 0.0, None, ())
    median = statistics.median(periods)
    limit = gap_factor * median
    steps, active, gaps = 0, 0.0, []
    for start, period in zip(times, periods, strict=False):
        if median > 0 and period > limit:
            gaps.append(Gap(start, period))
        else:
            steps += 1
            active += period
    return StreamRate(len(times), steps, active, median, tuple(gaps))


def combined_rate(parts: Sequence[StreamRate]) -> float | None:
    """The rate of one stream over several captures: each one's spans, never across two."""
    steps = sum(p.steps for p in parts)
    active = sum(p.active_s for p in parts)
    return steps / active if steps and active > 0 else None
