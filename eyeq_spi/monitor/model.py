"""What the monitor shows, independent of where it comes from: rates against nominal over a
sliding window (by the one definition of a stream's rate, docs/dissector.md "Rates"), link
counters, errors, state transitions and the current scene."""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field

from eyeq_spi.catalog.messages import Catalog
from eyeq_spi.plot.collect import GAP_PERIODS
from eyeq_spi.plot.perceived import Scene
from eyeq_spi.stream_rate import stream_rate

RATE_WINDOW = 2.0  # seconds of history behind each rate
MIN_SPAN = 0.75  # s of a stream's history before its rate is called low or high (13 counts
# at 18 Hz: one message more or less is 7 %, well inside the §7.1.4 tolerance band of 15 %)


@dataclass(frozen=True)
class RateRow:
    name: str
    count: int
    hz: float | None  # None until the window holds two messages
    nominal_hz: float | None
    status: str  # "ok" | "low" | "high" | "stopped" | "-"
    gaps: int = 0  # gaps inside the window, left out of the rate (stream_rate)


@dataclass
class Snapshot:
    source: str
    now: float  # source time: virtual, real or capture seconds
    state_label: str  # "host state" or "EyeQ Main_State (0x41)"
    state: str
    transitions: list[tuple[float, str, str, str]] = field(default_factory=list)
    rates: list[RateRow] = field(default_factory=list)
    link: dict[str, int] = field(default_factory=dict)
    errors: dict[str, int] = field(default_factory=dict)
    stale: list[str] = field(default_factory=list)
    scene: Scene = field(default_factory=Scene)
    problem: str | None = None
    done: bool = False
    transitions_seen: int = 0  # of which ``transitions`` holds the last few (0: as many)

    @property
    def transitions_total(self) -> int:
        return max(self.transitions_seen, len(self.transitions))


def band(rate_hz: float | None, tolerance_ms: tuple[float, float] | None
         ) -> tuple[float, float] | None:
    """Rates whose period is within the tolerance of the nominal period (§7.1.4 tables)."""
    if not rate_hz or tolerance_ms is None:
        return None
    p_ms = 1000.0 / rate_hz
    lo, hi = p_ms + tolerance_ms[0], p_ms + tolerance_ms[1]
    return (1000.0 / hi, 1000.0 / lo if lo > 0 else float("inf"))


class RateMeter:
    """Message rates over the last ``window`` seconds, by the one definition of a stream's rate
    (:func:`eyeq_spi.stream_rate.stream_rate`), from the arrival times inside the window."""

    def __init__(self, cat: Catalog, window: float = RATE_WINDOW) -> None:
        self.window = window
        self._times: dict[str, deque[float]] = {}
        self._counts: dict[str, int] = {}
        self._now = 0.0
        self._nominal = {msg.name: (msg.rate_hz, msg.tolerance_ms) for msg in cat.messages}

    def arrived(self, name: str, time: float) -> None:
        """A message ``name`` arrived (or was sent) at ``time`` (source seconds, rising)."""
        times = self._times.get(name)
        if times is None:
            times = self._times[name] = deque()
        times.append(time)
        while times[0] < time - self.window:
            times.popleft()

    def tick(self, now: float, counts: Mapping[str, int]) -> None:
        """The source's time at a redraw, and the messages it counted since its start."""
        self._now = now
        self._counts = dict(counts)

    def rows(self) -> list[RateRow]:
        now = self._now
        out = []
        for name in sorted(set(self._counts) | set(self._times)):
            times = self._times.get(name, deque())
            while times and times[0] < now - self.window:
                times.popleft()  # the last arrival stays while the window holds it
            nominal, tol = self._nominal.get(name, (None, None))
            rate = stream_rate(times)
            hz = rate.rate_hz
            limits = band(nominal, tol)
            status = "-"
            if not times and name in self._times:
                hz = 0.0  # nothing inside the window
            if nominal and name in self._times:
                last = times[-1] if times else None
                if last is None or now - last > GAP_PERIODS / nominal:
                    # its rate now is 0, whatever it was earlier in the window
                    status, hz = "stopped", 0.0
                elif hz is None or rate.active_s < MIN_SPAN:
                    status = "-"  # too few messages yet to call the rate low or high
                elif limits is not None and hz < limits[0]:
                    status = "low"
                elif limits is not None and hz > limits[1]:
                    status = "high"
                else:
                    status = "ok"
            out.append(RateRow(name, self._counts.get(name, 0), hz, nominal, status,
                               len(rate.gaps)))
        return out
