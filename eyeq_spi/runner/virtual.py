"""Virtual-clock runner: jumps from one deadline to the next, so a minute of protocol runs in
however long the CPU needs (tests, ``demo --virtual-time``, the campaigns).

Event-driven, through the nodes' public calls only: transfers in flight wait in a deadline heap,
each node's deadline is cached until the node is touched, and the calls that remain are those a
polling loop would make that can change something, in the same order
(``tests/test_runner_virtual.py`` compares both; docs/performance.md, "The emulator in virtual
time", says what counts as a touch and what ``SELF_CONTAINED`` promises)."""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Callable

from eyeq_spi.phy.base import Adapter
from eyeq_spi.runner.node import Node

Tap = Callable[[int, float, bytes], None]
"""Called for every transfer a node puts on the wire: (node index, time, transfer)."""


class VirtualRunner:
    """Runs nodes, each bound to an adapter (normally the two ends of a memory pair);
    ``latency``: from a node handing over a transfer to the peer receiving it (128 bytes at the
    seed's 10 MHz SPI clock)."""

    verify = False
    """Tests set this: every cached deadline is checked against a fresh ``get_timer()``."""

    def __init__(
        self,
        nodes: list[tuple[Node, Adapter]],
        *,
        latency: float = 128 * 8 / 10_000_000,
        start: float = 0.0,
        tap: Tap | None = None,
        max_steps_per_instant: int = 100_000,
        self_contained: frozenset[int] = frozenset(),
    ) -> None:
        self.nodes = nodes
        self.latency = latency
        self.now = start
        self.tap = tap
        # the deadline heap of transfers in flight: (arrival time, sequence, node index, bytes)
        self._transit: list[tuple[float, int, int, bytes]] = []
        self._seq = 0
        self._max_steps = max_steps_per_instant
        self.wall_s = 0.0  # wall-clock and CPU time spent in run_until
        self.cpu_s = 0.0
        count = len(nodes)
        self._timer: list[float | None] = [None] * count  # cached get_timer()
        self._known = [False] * count  # _timer[i] is still what get_timer() would say
        self._quiet = [False] * count  # data_to_send(now) gave nothing and nothing touched it since
        self._fresh = [True] * count  # touched since its last data_to_send
        # SELF_CONTAINED nodes (see Node; a subclass does not inherit the promise) and those the
        # caller declares so (it wired their one outside effect, the reset line, to touch_all)
        self._alone = [vars(type(node)).get("SELF_CONTAINED") is True or i in self_contained
                       for i, (node, _) in enumerate(nodes)]

    # -- caches -----------------------------------------------------------------------------
    def touch_all(self) -> None:
        """Forget every node's cached deadline and quiet state (after code drove a node from
        outside, or a node acted on another: the emulator's reset line)."""
        count = len(self.nodes)
        self._known[:] = [False] * count
        self._quiet[:] = [False] * count
        self._fresh[:] = [True] * count

    def _touch(self, index: int) -> None:
        """Node ``index`` received a transfer or handled a timer."""
        if self._alone[index]:
            self._known[index] = self._quiet[index] = False
            self._fresh[index] = True
        else:  # it may have acted on another node (the host's reset line powers the EyeQ up)
            self.touch_all()

    def _deadline(self, index: int) -> float | None:
        if not self._known[index]:
            self._known[index] = True
            timer = self._timer[index] = self.nodes[index][0].get_timer()
            return timer
        timer = self._timer[index]
        if self.verify:
            fresh = self.nodes[index][0].get_timer()
            if fresh != timer:
                raise AssertionError(f"node {index}: cached deadline {timer} but get_timer() is "
                                     f"{fresh}")
        return timer

    def _drain(self, sender: int) -> None:
        """Put what reached the other nodes' adapters in flight, to arrive ``latency`` later."""
        at = self.now + self.latency
        for peer, (_, other) in enumerate(self.nodes):
            if peer == sender:
                continue
            while (transfer := other.recv(0)) is not None:
                # a memory pair delivers to exactly one peer, so attribute it to `peer`
                self._seq += 1
                heapq.heappush(self._transit, (at, self._seq, peer, transfer))

    # -- one instant ------------------------------------------------------------------------
    def _pump(self, drain_all: bool = False) -> None:
        """Move transfers until nothing more happens at ``now``. ``drain_all``: look at every
        adapter in the first round (something may have been put there from outside)."""
        nodes, now, transit, tap = self.nodes, self.now, self._transit, self.tap
        quiet, known, fresh, alone = self._quiet, self._known, self._fresh, self._alone
        timers, cached = self._timer, not self.verify
        count = len(nodes)
        for _ in range(self._max_steps):
            progress = False
            for index in range(count):
                if quiet[index]:
                    if drain_all:
                        self._drain(index)
                    continue
                node, adapter = nodes[index]
                outs = node.data_to_send(now)
                if outs:
                    progress = True
                    known[index] = False
                    for out in outs:
                        if tap is not None:
                            tap(index, now, out)
                        adapter.send(out)
                    if alone[index]:
                        # a SELF_CONTAINED node hands over all that is due in one call
                        quiet[index] = True
                        if self.verify and node.data_to_send(now):
                            raise AssertionError(f"node {index}: more to send at {now} after a "
                                                 "call that handed over")
                else:
                    # handing over nothing can still move a deadline (a request queued behind a
                    # full window); a SELF_CONTAINED node promises only the first call can
                    if fresh[index] or not alone[index]:
                        known[index] = False
                    quiet[index] = True
                fresh[index] = False
                if outs or drain_all:
                    self._drain(index)
            drain_all = False
            while transit and transit[0][0] <= now:
                _, _, to, transfer = heapq.heappop(transit)
                nodes[to][0].receive_data(transfer, now)
                self._touch(to)
                progress = True
            for index in range(count):
                timer = timers[index] if cached and known[index] else self._deadline(index)
                if timer is not None and timer <= now:
                    nodes[index][0].handle_timer(now)
                    self._touch(index)
                    progress = True
            if not progress:
                return
        raise RuntimeError(f"no quiescence at t={self.now}: a node keeps asking for work")

    def _next(self) -> float | None:
        best = self._transit[0][0] if self._transit else None
        for index in range(len(self.nodes)):
            due = self._deadline(index)
            if due is not None and (best is None or due < best):
                best = due
        return best

    # -- running ----------------------------------------------------------------------------
    def run_until(
        self, t_end: float, *, stop: Callable[[], bool] | None = None, realtime: bool = False,
        pace_origin: tuple[float, float] | None = None,
    ) -> float:
        """Advance to ``t_end`` (or until ``stop()`` is true); returns the time reached.
        ``realtime`` paces virtual time to the wall clock from ``pace_origin`` (``(perf_counter,
        virtual time)``, default: this call's start), so a run made of many calls keeps up."""
        w0, c0 = time.perf_counter(), time.process_time()
        pace = (pace_origin or (w0, self.now)) if realtime else None
        try:
            return self._run(t_end, stop, pace)
        finally:
            self.wall_s += time.perf_counter() - w0
            self.cpu_s += time.process_time() - c0

    def _new_instant(self, at: float) -> None:
        """Move the clock to ``at``. A quiet node (nothing to send, untouched since) whose deadline
        is later stays quiet: it is not asked ``data_to_send`` (the Node contract)."""
        if at == self.now:
            return
        self.now = at
        quiet, known, fresh, timers = self._quiet, self._known, self._fresh, self._timer
        for index in range(len(quiet)):
            if quiet[index]:
                timer = timers[index]
                if fresh[index] or not known[index] or (timer is not None and timer <= at):
                    quiet[index] = False
                elif self.verify and self.nodes[index][0].data_to_send(at):
                    raise AssertionError(f"node {index}: quiet with deadline {timer} but has "
                                         f"something to send at {at}")

    def _run(
        self, t_end: float, stop: Callable[[], bool] | None, pace: tuple[float, float] | None,
    ) -> float:
        self.touch_all()  # nodes may have been driven from outside since the last call
        self._pump(drain_all=True)
        lone = stop is None and pace is None and not self.verify and len(self.nodes) == 2 \
            and all(self._alone) and self.latency > 0
        while stop is None or not stop():
            if stop is not None:
                self.touch_all()
            if lone:
                self._lone_instants(t_end)
            nxt = self._next()
            if nxt is None or nxt > t_end:
                if pace is not None:  # a quiet stretch takes its wall time too
                    ahead = (t_end - pace[1]) - (time.perf_counter() - pace[0])
                    if ahead > 0:
                        time.sleep(ahead)
                self._new_instant(max(self.now, t_end))
                self._pump()
                break
            if pace is not None:
                ahead = (nxt - pace[1]) - (time.perf_counter() - pace[0])
                if ahead > 0:
                    time.sleep(ahead)
            self._new_instant(max(self.now, nxt))
            self._pump()
        return self.now

    def _lone_instants(self, t_end: float) -> None:
        """Run the instants up to ``t_end`` at which exactly one thing happens (one transfer
        arrives, or one node's deadline comes) for two self-contained quiet nodes: the calls
        ``_pump`` would make on the one node concerned, in its order. Returns at the first other
        instant, with the caches as ``_pump`` would have left them."""
        quiet, known, fresh, timers, transit = (self._quiet, self._known, self._fresh,
                                                self._timer, self._transit)
        if not (quiet[0] and quiet[1] and known[0] and known[1]) or fresh[0] or fresh[1]:
            return
        nodes, inf = self.nodes, math.inf
        while True:
            t0 = inf if timers[0] is None else timers[0]
            t1 = inf if timers[1] is None else timers[1]
            arrival = transit[0][0] if transit else inf
            at = min(t0, t1, arrival, inf)
            if at > t_end or at == inf or at < self.now \
                    or (t0 == at) + (t1 == at) + (arrival == at) != 1 \
                    or (arrival == at and len(transit) > 1 and _second(transit) <= at):
                return  # nothing more to do here, or more than one thing at t
            self.now = at
            if arrival == at:
                _, _, side, transfer = heapq.heappop(transit)
                node = nodes[side][0]
                node.receive_data(transfer, at)
                if not known[1 - side]:  # it acted on the other node (the reset line)
                    self._finish_instant(at, 0)
                    return
                timer = node.get_timer()
                known_side = timer is None or timer > at
                if not known_side:
                    node.handle_timer(at)
                    if not known[1 - side]:
                        self._finish_instant(at, side + 1)
                        return
                touched = True  # asked for data in the next round
            else:
                side = 0 if t0 == at else 1
                node, timer, known_side, touched = nodes[side][0], timers[side], True, False
            for _ in range(self._max_steps):  # _pump's rounds for node `side` alone
                outs = node.data_to_send(at)
                if outs:
                    known_side = False
                    adapter = nodes[side][1]
                    for out in outs:
                        if self.tap is not None:
                            self.tap(side, at, out)
                        adapter.send(out)
                    self._drain(side)
                elif touched:
                    known_side = False
                touched = False
                if not known_side:
                    timer, known_side = node.get_timer(), True
                if timer is not None and timer <= at:
                    node.handle_timer(at)
                    if not known[1 - side]:
                        self._finish_instant(at, side + 1)
                        return
                    known_side, touched = False, True
                    continue
                break
            else:
                raise RuntimeError(f"no quiescence at t={at}: a node keeps asking for work")
            timers[side] = timer

    def _finish_instant(self, at: float, first: int) -> None:
        """A node's call acted on the other node (the reset line): finish the instant as ``_pump``
        would from its timer checks at node ``first``."""
        for index in range(first, len(self.nodes)):
            timer = self._deadline(index)
            if timer is not None and timer <= at:
                self.nodes[index][0].handle_timer(at)
                self._touch(index)
        self._pump()

    def run_for(self, duration: float, *, stop: Callable[[], bool] | None = None) -> float:
        return self.run_until(self.now + duration, stop=stop)


def _second(transit: list[tuple[float, int, int, bytes]]) -> float:
    """The arrival time of the second transfer in flight (a heap's second smallest)."""
    if len(transit) == 2:
        return transit[1][0]
    return min(transit[1][0], transit[2][0])
