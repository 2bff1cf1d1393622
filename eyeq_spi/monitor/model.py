"""What the monitor shows, independent of where it comes from: rates against nominal over a
sliding window, link counters, errors, state transitions and the current scene."""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field

from eyeq_spi.catalog.messages import Catalog
from eyeq_spi.plot.collect import GAP_PERIODS
from eyeq_spi.plot.perceived import Scene

RATE_WINDOW = 2.0  # seconds of history behind each rate
MIN_SPAN = 0.75  # s of a stream's history before its rate is called low or high (13 counts
# at 18 Hz: one message more or less is 7 %, well inside the §7.1.4 tolerance band of 15 %)


@dataclass(frozen=True)
class RateRow:
    name: str
    count: int
    hz: float | None  # None until the window has two snapshots
    nominal_hz: float | None
    band_hz: tuple[float, float] | None  # the rates the period tolerance allows
    status: str  # "ok" | "low" | "high" | "stopped" | "-"


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
    """Message rates from cumulative counts sampled at each tick (no per-message cost)."""

    def __init__(self, cat: Catalog, window: float = RATE_WINDOW) -> None:
        self.cat = cat
        self.window = window
        self._hist: deque[tuple[float, dict[str, int]]] = deque()
        self._last_change: dict[str, float] = {}
        self._first: dict[str, tuple[float, int]] = {}  # tick before a message's first arrival
        self._nominal: dict[str, tuple[float | None, tuple[float, float] | None]] = {}

    def _nominal_of(self, name: str) -> tuple[float | None, tuple[float, float] | None]:
        if name not in self._nominal:
            try:
                msg = self.cat.message(name)
                self._nominal[name] = (msg.rate_hz, msg.tolerance_ms)
            except Exception:
                self._nominal[name] = (None, None)
        return self._nominal[name]

    def tick(self, now: float, counts: Mapping[str, int],
             last_seen: Mapping[str, float] | None = None) -> None:
        """``last_seen``: when each message last arrived, where the source knows it; without
        it a change is dated at the tick that saw it, which is coarse when ticks are sparse (a
        replay at 4x redraws every 0.7 s of capture time, longer than a stream's stop gap)."""
        snap = dict(counts)
        prev = self._hist[-1][1] if self._hist else {}
        for k, v in snap.items():
            if k not in self._first and v:  # counted from the last tick that knew it (at 0),
                # else from the first that saw it
                self._first[k] = (self._hist[-1][0], prev[k]) if k in prev else (now, v)
            if v != prev.get(k, 0) or k not in self._last_change:
                self._last_change[k] = now
        if last_seen:
            self._last_change.update(last_seen)
        self._hist.append((now, snap))
        while len(self._hist) > 2 and now - self._hist[1][0] >= self.window:
            self._hist.popleft()

    def rows(self) -> list[RateRow]:
        if not self._hist:
            return []
        t1, c1 = self._hist[-1]
        t0, c0 = self._hist[0]
        out = []
        for name in sorted(c1):
            nominal, tol = self._nominal_of(name)
            # the window starts at the tick that first saw the message, if later: a stream
            # that began 1 s ago is not at half its rate over a 2 s window
            ts, cs = t0, c0.get(name, 0)
            first = self._first.get(name)
            if first is not None and first[0] > t0:
                ts, cs = first
            hz = (c1[name] - cs) / (t1 - ts) if t1 > ts else None
            limits = band(nominal, tol)
            status = "-"
            if nominal and hz is not None:
                silent = t1 - self._last_change.get(name, t1)
                if silent > GAP_PERIODS / nominal:
                    # its rate now is 0: the 2 s average would still read up to the nominal
                    # rate beside "stopped" (a "17.9 Hz" stream that stopped 0.2 s ago)
                    status, hz = "stopped", 0.0
                elif t1 - ts < MIN_SPAN:
                    status = "-"  # too few messages yet to call the rate low or high
                elif limits is not None and hz < limits[0]:
                    status = "low"
                elif limits is not None and hz > limits[1]:
                    status = "high"
                else:
                    status = "ok"
            out.append(RateRow(name, c1[name], hz, nominal, limits, status))
        return out
