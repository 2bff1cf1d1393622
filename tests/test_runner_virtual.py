"""The event-driven VirtualRunner makes the same transfers at the same virtual times as
the polling loop it replaced: both run the same emulations and their tap traces are compared
transfer by transfer (node, time, bytes)."""

from __future__ import annotations

import heapq
import random
from collections.abc import Iterator

import pytest

from eyeq_spi.emulator import HOST_ALONE, Emulation, build
from eyeq_spi.host.machine import HostState
from eyeq_spi.phy.base import Adapter
from eyeq_spi.phy.memory import MemoryAdapter
from eyeq_spi.runner.node import Node
from eyeq_spi.runner.virtual import VirtualRunner
from eyeq_spi.sim.config import SimConfig

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

Trace = list[tuple[int, float, bytes]]


class PollingRunner(VirtualRunner):
    """The runner before it became event-driven: every round asks every node for data and for
    its timer, and the next instant is the minimum over all of them."""

    def _pump(self, drain_all: bool = False) -> None:
        for _ in range(self._max_steps):
            progress = False
            for i, (node, adapter) in enumerate(self.nodes):
                for out in node.data_to_send(self.now):
                    progress = True
                    if self.tap is not None:
                        self.tap(i, self.now, out)
                    adapter.send(out)
                for j, (_, other) in enumerate(self.nodes):
                    if j == i:
                        continue
                    while (t := other.recv(0)) is not None:
                        self._seq += 1
                        heapq.heappush(self._transit, (self.now + self.latency, self._seq, j, t))
                        progress = True
            while self._transit and self._transit[0][0] <= self.now:
                _, _, to, transfer = heapq.heappop(self._transit)
                self.nodes[to][0].receive_data(transfer, self.now)
                progress = True
            for node, _ in self.nodes:
                timer = node.get_timer()
                if timer is not None and timer <= self.now:
                    node.handle_timer(self.now)
                    progress = True
            if not progress:
                return
        raise RuntimeError("no quiescence")

    def _next(self) -> float | None:
        times = [t for n, _ in self.nodes if (t := n.get_timer()) is not None]
        if self._transit:
            times.append(self._transit[0][0])
        return min(times) if times else None


def _lossy(seed: int, p: float) -> object:
    rng = random.Random(seed)

    def mangle(t: bytes) -> list[bytes]:
        r = rng.random()
        if r < p:
            return []  # dropped
        if r < 2 * p:
            return [t, t]  # duplicated
        if r < 3 * p:
            return [t[:-1] + bytes([t[-1] ^ 0x5A])]  # corrupted CRC
        return [t]

    return mangle


def _emulation(polling: bool, cfg: SimConfig, loss: float = 0.0) -> tuple[Emulation, Trace]:
    trace: Trace = []
    emu = build(sim_config=cfg, keep_rx_times=False)
    cls = PollingRunner if polling else VirtualRunner
    emu.runner = cls(emu.runner.nodes, tap=lambda i, t, b: trace.append((i, t, b)),
                     self_contained=HOST_ALONE)
    if loss:
        for k, (_, adapter) in enumerate(emu.runner.nodes):
            assert isinstance(adapter, MemoryAdapter)
            adapter.mangle = _lossy(k, loss)  # type: ignore[assignment]
    return emu, trace


@pytest.fixture
def verify() -> Iterator[None]:
    """Every cached deadline is checked against a fresh get_timer() while the test runs."""
    VirtualRunner.verify = True
    try:
        yield
    finally:
        VirtualRunner.verify = False


CASES = {
    "full_load": (SimConfig(objects=15, signs=20, light_spots=15), 0.0, 2.5),
    "eyeq_resets_itself": (SimConfig(reset_at=1.2), 0.0, 2.5),
    "lossy_link": (SimConfig(), 0.02, 2.5),
    # boot test failures: the host resets the EyeQ through its reset line (touch_all)
    "boot_failures_reset_line": (SimConfig(boot_test_failures=1, boot_failures=2), 0.0, 2.5),
    "late_and_dropped_replies": (
        SimConfig(reply_delay=0.03, drop_replies={"GetEyeQExtendedState": 2}), 0.0, 2.0),
}


@pytest.mark.parametrize("case", list(CASES))
def test_same_transfers_at_the_same_times_as_polling(case: str, verify: None) -> None:
    _same_as_polling(case)


@pytest.mark.parametrize("case", [c for c in CASES if c != "lossy_link"])
def test_lone_instants_give_the_same_transfers_as_polling(case: str) -> None:
    """Without ``verify`` the runner takes the instants at which one thing happens on the one
    node concerned (``_lone_instants``): still the polling loop's transfers and times. (Not
    on the lossy link: there the link's ``fifoNonEmptyCounter``, which counts the calls that
    find the window full, depends on how often a runner asks, and it travels in 0xA0.)"""
    _same_as_polling(case)


def _same_as_polling(case: str) -> None:
    cfg, loss, seconds = CASES[case]
    traces = []
    for polling in (True, False):
        emu, trace = _emulation(polling, SimConfig(**vars(cfg)), loss)
        emu.run_for(seconds)
        traces.append(trace)
    old, new = traces
    assert len(old) > 1000
    first = next((k for k, (a, b) in enumerate(zip(old, new, strict=False)) if a != b), None)
    where = None if first is None else (old[first][:2], new[first][:2])
    assert first is None, f"first difference at transfer {first}: {where}"
    assert len(old) == len(new)


def test_host_driven_from_outside_between_runs_is_seen(verify: None) -> None:
    """A mode switch requested between run_until calls (as the CLI and campaigns do) is picked
    up: the caches are dropped at every call."""
    traces = []
    for polling in (True, False):
        emu, trace = _emulation(polling, SimConfig())
        emu.run_for(1.5)
        assert emu.host.state is HostState.RUNNING_VISION
        emu.host.switch_mode("DV", emu.runner.now)
        emu.run_for(1.0)
        traces.append(trace)
    assert traces[0] == traces[1]


def test_a_cached_deadline_that_goes_stale_is_caught() -> None:
    """The verify switch the tests above rely on can fail: a node that moves its deadline
    without being touched is reported."""

    class Sneaky:
        def __init__(self) -> None:
            self.t = 1.0
            self.calls = 0

        def receive_data(self, transfer: bytes, now: float) -> None: ...

        def data_to_send(self, now: float) -> list[bytes]:
            return []

        def get_timer(self) -> float | None:
            self.calls += 1
            return self.t - 0.001 * self.calls  # moves between two calls, with no touch

        def handle_timer(self, now: float) -> None:
            self.t = now + 1.0

    node: Node = Sneaky()
    runner = VirtualRunner([(node, MemoryAdapter())])
    runner.verify = True
    with pytest.raises(AssertionError, match="cached deadline"):
        runner.run_until(5.0)


def test_adapter_fed_from_outside_is_delivered() -> None:
    a, b = MemoryAdapter(), MemoryAdapter()
    a.peer, b.peer = b, a
    got: list[tuple[bytes, float]] = []

    class Sink:
        def receive_data(self, transfer: bytes, now: float) -> None:
            got.append((transfer, now))

        def data_to_send(self, now: float) -> list[bytes]:
            return []

        def get_timer(self) -> float | None:
            return None

        def handle_timer(self, now: float) -> None: ...

    nodes: list[tuple[Node, Adapter]] = [(Sink(), a), (Sink(), b)]
    runner = VirtualRunner(nodes, latency=0.001)
    runner.run_until(1.0)
    a.inbox.append(b"x")
    runner.run_until(2.0)
    assert got == [(b"x", 1.001)]  # picked up at once, delivered after the latency


def test_self_contained_is_not_inherited() -> None:
    """A subclass that rewrites a node's output (a conformance mutant) must declare the promise
    itself: it is not taken from the parent class."""
    from eyeq_spi.conformance.mutants import NoAck
    from eyeq_spi.sim.eyeq import SimulatedEyeQ

    a, b = MemoryAdapter(), MemoryAdapter()
    runner = VirtualRunner([(SimulatedEyeQ(), a), (NoAck(), b)])
    assert runner._alone == [True, False]
