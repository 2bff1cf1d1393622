"""Express instants for :class:`~eyeq_spi.runner.virtual.VirtualRunner`: two self-contained
nodes on a clean in-memory wire, one thing happening per instant.

At full load almost every instant of an emulation is one of two kinds: one transfer arrives at
one node (a DATA frame, which the node ACKs in the same instant, or an ACK), or one node's own
deadline comes (its next DATA frame is due under frameFlowControl, a DASP message or a timer of
the node). For such an instant the general loop (``VirtualRunner._pump``) asks every node in
rounds, drains every adapter and keeps its caches for all nodes; here the same calls are made on
the one node concerned, in the same order, with the same arguments and the same ``now``, and
its transfers are put in flight with the same arrival times and heap order. Whatever the node
decides (an ACK, a NAK, a timer, a reset) is its own code's decision: nothing is predicted, so
faults and resets inside a node take the same course on both paths.

The general loop takes over, instant by instant, whenever an instant is not of these kinds (two
arrivals or deadlines at the same time, a node whose timer and an arrival coincide), and for the
whole run when the wire is not clean (a ``mangle`` fault hook on an adapter, a closed adapter,
transfers put into an adapter from outside), when a node does not promise to be self-contained
(a conformance shim or mutant), when ``verify`` is on, when a ``stop`` condition is polled or
the run is paced to the wall clock, or when ``EYEQ_SPI_EXACT=1`` asks for the reference path
(``tests/test_runner_virtual.py`` compares both transfer by transfer).
"""

from __future__ import annotations

import heapq

from eyeq_spi.phy.memory import MemoryAdapter
from eyeq_spi.runner.virtual_types import RunnerState

_INF = float("inf")


class Express:
    """The fast instant loop of one runner (see the module's description)."""

    def __init__(self, runner: RunnerState) -> None:
        self.runner = runner
        (self.n0, a0), (self.n1, a1) = runner.nodes
        assert isinstance(a0, MemoryAdapter) and isinstance(a1, MemoryAdapter)
        self.a0, self.a1 = a0, a1
        self.instants = 0  # instants this loop handled (the tests check that it did work)
        self.absorbed = 0  # DATA frames a node took and ACKed in one step
        # a node's own class may offer ``express_absorb(transfer, now) -> list[bytes] | None``:
        # receive_data, handle_timer and data_to_send at ``now`` in one step where it can tell
        # that they would do nothing else (not inherited, as SELF_CONTAINED)
        self.absorbs = tuple(
            getattr(n, "express_absorb", None) if "express_absorb" in vars(type(n)) else None
            for n in (self.n0, self.n1))

    @staticmethod
    def eligible(runner: RunnerState) -> bool:
        """Two self-contained nodes on the two ends of one memory pair, a positive latency."""
        if len(runner.nodes) != 2 or not all(runner._alone) or runner.latency <= 0:
            return False
        a0, a1 = runner.nodes[0][1], runner.nodes[1][1]
        return (isinstance(a0, MemoryAdapter) and isinstance(a1, MemoryAdapter)
                and a0.peer is a1 and a1.peer is a0)

    def _clean(self) -> bool:
        a0, a1 = self.a0, self.a1
        return not (a0.mangle is not None or a1.mangle is not None or a0.closed or a1.closed
                    or a0.inbox or a1.inbox)

    def run(self, t_end: float) -> None:
        """Handle instants up to ``t_end`` while each is an express instant; return at the first
        that is not (the runner's general loop handles it), with the runner's caches as the
        general loop would have left them."""
        r = self.runner
        quiet, known, fresh, timers, transit = r._quiet, r._known, r._fresh, r._timer, r._transit
        if not (quiet[0] and quiet[1] and known[0] and known[1]) or fresh[0] or fresh[1]:
            return
        if not self._clean():
            return
        steps = r._max_steps
        nodes = (self.n0, self.n1)
        absorbs = self.absorbs
        while True:
            t0, t1 = timers[0], timers[1]
            t0 = _INF if t0 is None else t0
            t1 = _INF if t1 is None else t1
            ta = transit[0][0] if transit else _INF
            t = min(t0, t1, ta)
            if t > t_end or t == _INF:
                return
            # one thing at t, and the clock moves forward: else the general loop decides
            if t < r.now or (t0 == t) + (t1 == t) + (ta == t) != 1 or (
                    ta == t and len(transit) > 1 and _second(transit) <= t):
                return
            r.now = t
            self.instants += 1
            if ta == t:
                _, _, j, transfer = heapq.heappop(transit)
                node = nodes[j]
                absorb = absorbs[j]
                outs = absorb(transfer, t) if absorb is not None else None
                if outs is not None:
                    # receive_data, handle_timer and data_to_send in one step (the node's hook)
                    self.absorbed += 1
                    self._hand_over(j, t, outs)
                    timer = node.get_timer()
                    if timer is not None and timer <= t:
                        raise RuntimeError(f"node {j}: due at {t} after absorbing a frame")
                    timers[j] = timer
                    continue
                node.receive_data(transfer, t)
                if not known[1 - j]:  # the node acted on the other one (the reset line)
                    self._general(t, 0)
                    return
                timer = node.get_timer()
                if timer is not None and timer <= t:
                    node.handle_timer(t)
                    if not known[1 - j]:
                        self._general(t, j + 1)
                        return
                    known_j = False
                else:
                    known_j = True
                is_fresh = True  # touched: asked for data in the next round
            else:
                j = 0 if t0 == t else 1
                node = nodes[j]
                timer, known_j, is_fresh = timers[j], True, False
            # the rounds of the general loop for node j alone (the other node is quiet with a
            # later deadline, and nothing it sends arrives before t + latency)
            other = 1 - j
            for _ in range(steps):
                outs = node.data_to_send(t)
                if outs:
                    known_j = False
                    self._hand_over(j, t, outs)
                elif is_fresh:
                    known_j = False
                is_fresh = False
                if not known_j:
                    timer = node.get_timer()
                    known_j = True
                if timer is not None and timer <= t:
                    node.handle_timer(t)
                    if not known[other]:
                        self._general(t, j + 1)
                        return
                    known_j, is_fresh = False, True
                    continue
                break
            else:
                raise RuntimeError(f"no quiescence at t={t}: a node keeps asking for work")
            timers[j] = timer
            if not self._clean():  # a node closed or fed an adapter: the general loop decides
                return

    def _hand_over(self, j: int, t: float, outs: list[bytes]) -> None:
        """Put what node ``j`` handed over at ``t`` in flight, as the general loop's tap, adapter
        and drain do."""
        r = self.runner
        tap, at, other = r.tap, t + r.latency, 1 - j
        sent, got = (self.a0, self.a1)[j].stats, (self.a0, self.a1)[other].stats
        for out in outs:
            if tap is not None:
                tap(j, t, out)
            size = len(out)
            sent.transfers_sent += 1
            sent.bytes_sent += size
            got.transfers_received += 1
            got.bytes_received += size
            r._seq += 1
            heapq.heappush(r._transit, (at, r._seq, other, out))

    def _general(self, t: float, first: int) -> None:
        """A node call acted on the other node (``touch_all``, as the host's reset line does):
        finish the instant as the general loop would from where it is, in its timer checks at
        node ``first``."""
        r = self.runner
        for i in range(first, 2):
            timer = r._deadline(i)
            if timer is not None and timer <= t:
                r.nodes[i][0].handle_timer(t)
                r._touch(i)
        r._pump()


def _second(transit: list[tuple[float, int, int, bytes]]) -> float:
    """The arrival time of the second transfer in flight (a heap's second-smallest)."""
    if len(transit) == 2:
        return transit[1][0]
    return min(transit[1][0], transit[2][0])
