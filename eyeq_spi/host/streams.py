"""Stale detection of the EyeQ's DASP streams in Running Vision: a stream is stale once it
has been silent for ``HostConfig.stale_periods`` of its periods; every ``STALE_CHECK`` seconds
the host looks (:meth:`StreamWatch.check`)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable

from eyeq_spi.catalog.messages import Catalog, MessageDef, SwKey
from eyeq_spi.host.config import STALE_CHECK


def expected_streams(cat: Catalog, sw: SwKey, mode: str) -> list[MessageDef]:
    """The DASP messages the EyeQ sends in ``mode`` (``APP``: Running Vision) in release
    ``sw``."""
    return [m for m in cat.messages
            if m.protocol == "DASP" and m.direction == "e2h" and m.exists_in(sw)
            and mode in m.modes]


class StreamWatch:
    """When each expected DASP stream was last received, and which are stale."""

    def __init__(self) -> None:
        self.last_rx: dict[str, float] = {}
        self.stale: set[str] = set()
        self.limits: dict[str, float] = {}
        self.next_check = 0.0

    def watch(self, expected: Iterable[MessageDef], stale_periods: float, now: float) -> None:
        """Running Vision entered: expect these streams from ``now`` on."""
        expected = list(expected)
        self.last_rx = {m.name: now for m in expected}
        self.limits = {m.name: stale_periods / (m.rate_hz or 18.0) for m in expected}
        self.next_check = now + STALE_CHECK
        self.stale.clear()

    def stop(self) -> None:
        """Expect nothing (a fatal EyeQ sends no DASP; a mode switch stops it)."""
        self.last_rx.clear()

    def clear(self) -> None:
        self.last_rx.clear()
        self.stale.clear()

    def received(self, name: str, now: float) -> None:
        self.last_rx[name] = now
        self.stale.discard(name)

    def check(self, now: float, events: Counter[str]) -> None:
        """The streams silent for longer than their limit become stale (counted once each in
        ``events``); the next check is ``STALE_CHECK`` later."""
        self.next_check = now + STALE_CHECK
        for name, last in self.last_rx.items():
            limit = self.limits.get(name)
            if limit is not None and name not in self.stale and now - last > limit:
                self.stale.add(name)
                events[name] += 1
