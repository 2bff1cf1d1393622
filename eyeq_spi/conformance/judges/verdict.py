"""Verdicts and the context judges read."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from eyeq_spi.conformance.trace import Trace

Span = tuple[float, float, float]
"""One violating measurement: (start, end, excess in seconds beyond its limit)."""
Verdict = Literal["pass", "fail", "skip", "inconclusive"]
VERDICTS: tuple[Verdict, ...] = ("pass", "fail", "skip", "inconclusive")


@dataclass(frozen=True)
class Outcome:
    """``advice``: what we recommend beyond the seed and the decisions; never a failure."""

    verdict: Verdict
    evidence: str
    advice: str = ""
    # a timing fail: each violating measurement, so that only our own stalls that overlap it
    # and are at least its excess can excuse it (load.py)
    spans: tuple[Span, ...] = ()


def ok(evidence: str) -> Outcome:
    return Outcome("pass", evidence)


def advise(evidence: str, advice: str) -> Outcome:
    """A pass that carries our recommendation (a rule neither the seed nor a decision states)."""
    return Outcome("pass", f"{evidence}; advice: {advice}", advice)


def bad(evidence: str, spans: list[Span] | tuple[Span, ...] = ()) -> Outcome:
    return Outcome("fail", evidence, spans=tuple(spans))


def unsure(evidence: str) -> Outcome:
    return Outcome("inconclusive", evidence)


def skip(evidence: str) -> Outcome:
    return Outcome("skip", evidence)


@dataclass
class Context:
    """What the judges see: one trace per session, and whether time was real."""

    dut: str
    realtime: bool
    traces: dict[str, Trace] = field(default_factory=dict)
    builtin: dict[str, Any] = field(default_factory=dict)  # our own DUT objects, per session

    @property
    def slack(self) -> float:
        """Extra seconds granted to deadlines measured across a real byte stream."""
        return 0.05 if self.realtime else 1e-6


def at(time_s: float) -> str:
    return f"t={time_s:.4f}s"
