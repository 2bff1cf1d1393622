from __future__ import annotations

import gc
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import pytest
from hypothesis import HealthCheck, settings

from eyeq_spi.link import LinkConfig, LinkConnection
from eyeq_spi.transport import TransportConnection

settings.register_profile(
    "ci", max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile("dev", max_examples=40, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")

Mangle = Callable[[int, bytes], list[bytes]]


@dataclass
class Wire:
    """A list of transfers in flight from one side; the test decides what gets through."""

    sent: list[bytes] = field(default_factory=list)


class Pair:
    """Two sans-IO connections wired back to back with hand-driven time (h11's ConnectionPair).

    ``mangle[side]`` maps (index of the transfer sent by that side, transfer) -> transfers the peer
    receives. ``run(until)`` advances a virtual clock from timer to timer.
    """

    def __init__(self, host: Any, eyeq: Any) -> None:
        self.sides = {"host": host, "eyeq": eyeq}
        self.now = 0.0
        self.mangle: dict[str, Mangle | None] = {"host": None, "eyeq": None}
        self.counts = {"host": 0, "eyeq": 0}
        self.log: list[tuple[float, str, bytes]] = []

    def _flush(self) -> bool:
        moved = False
        for name, conn in self.sides.items():
            peer = self.sides["eyeq" if name == "host" else "host"]
            for t in conn.data_to_send(self.now):
                moved = True
                idx = self.counts[name]
                self.counts[name] += 1
                self.log.append((self.now, name, t))
                m = self.mangle[name]
                for out in m(idx, t) if m else [t]:
                    peer.receive_data(out, self.now)
        return moved

    def run(self, until: float) -> None:
        while True:
            while self._flush():
                pass
            timers = [t for c in self.sides.values() if (t := c.get_timer()) is not None]
            due = [t for t in timers if t <= until]
            if not due:
                self.now = max(self.now, until)
                return
            self.now = max(self.now, min(due))
            for c in self.sides.values():
                t = c.get_timer()
                if t is not None and t <= self.now:
                    c.handle_timer(self.now)

    def events(self, side: str) -> list[Any]:
        out = []
        while (ev := self.sides[side].next_event()) is not None:
            out.append(ev)
        return out


@pytest.fixture
def link_pair() -> Pair:
    return Pair(LinkConnection(LinkConfig(role="host")), LinkConnection(LinkConfig(role="eyeq")))


@pytest.fixture
def transport_pair() -> Pair:
    return Pair(
        TransportConnection(LinkConfig(role="host")), TransportConnection(LinkConfig(role="eyeq"))
    )


@pytest.fixture(autouse=True)
def _collector_left_on() -> Iterator[None]:
    """Code that turns the cyclic garbage collector off (the real-time runner, the dissect
    pipeline) must turn it back on: a test that leaves it off fails here, by name, instead of
    a later test in the same process."""
    yield
    if not gc.isenabled():
        gc.enable()
        pytest.fail("the test left the cyclic garbage collector off")
