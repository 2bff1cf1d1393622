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

Most of those instants belong to messages: each frame is released, arrives and is ACKed, and
the ACK comes back. Once the sending node has let a frame go and everything in flight belongs to
its message, :meth:`Express._handover` hands the rest of that message across in
one step, with the instants the per-frame loop would go through computed (release, release +
latency, release + 2 × latency, one frame gap apart) and merged in time order, up to the first
instant that is anything else; the nodes' hooks (``express_run``, ``express_run_take``,
``express_take``) make the same changes to their links and transports as the per-frame calls.

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
from collections.abc import Callable
from typing import Any

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
        self.absorbs = tuple(_hook(n, "express_absorb") for n in (self.n0, self.n1))
        # and, for the handover of a whole message (see :meth:`_handover`): on the sending
        # node ``express_run(now) -> DataRun | None`` and ``express_run_take(run, released,
        # acked)``, on the receiving node ``express_take(frames, times, acks) -> int``
        self.runs = tuple(_hook(n, "express_run") for n in (self.n0, self.n1))
        self.run_takes = tuple(_hook(n, "express_run_take") for n in (self.n0, self.n1))
        self.takes = tuple(_hook(n, "express_take") for n in (self.n0, self.n1))
        self.handovers = 0  # messages (or their rests) handed over in one step
        self.sent_over = [0, 0]  # of them, those node 0 and node 1 sent
        self.handed = 0  # DATA frames received in those steps

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
            handed = False
            for _ in range(steps):
                outs = node.data_to_send(t)
                if outs:
                    known_j, handed = False, True
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
            if handed and self.runs[j] is not None:  # it may have let a frame go
                self._handover(j, t, t_end)

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

    def _handover(self, j: int, t: float, t_end: float) -> None:
        """Node ``j`` is in the middle of a message whose rest it can tell (``express_run``),
        and everything in flight belongs to it. Hand that rest over in one step, up to the
        first instant that is not one of its own: the releases (``s``, one frame gap apart),
        the arrivals at the other node, which ACKs at once (``b``), and the ACKs' arrivals
        back (``c``), each at the time the per-frame loop would reach it, with its transfers,
        tap calls, adapter statistics and heap order; whatever is still on its way at the end
        stays in (or goes into) the heap. The step stops before: a deadline of either node
        (the receiver's cached one, the sender's own, a transmit or ACK timeout), ``t_end``,
        two events at one time, a full window, a frame the receiver would not take at once
        (its ``express_take`` decides, frame by frame, as its ``express_absorb`` would). A
        message of one frame is handed over too, and a message the receiver takes whole is
        handed over up to its last ACK (the sender's ``express_run_take`` completes it), or up
        to the receiver's deadline as it stands once it has the message."""
        r = self.runner
        other = 1 - j
        take, run_take, run_hook = self.takes[other], self.run_takes[j], self.runs[j]
        if take is None or run_take is None or run_hook is None:
            return
        run = run_hook(t)
        if run is None:
            return
        transit = r._transit
        sent, nums, acks = run.sent, run.nums, run.acks
        n, i0 = len(nums), len(sent)
        if len(transit) > i0:
            return
        latency, gap = r.latency, run.gap
        # the per-frame loop's times: each release one gap after the last, each arrival one
        # latency after its hand-over
        s = list(sent)
        if n > i0:
            x = run.next_tx
            s.append(x)
            for _ in range(i0 + 1, n):
                x = x + gap
                s.append(x)
            after = x + gap
        else:
            after = run.next_tx
        timer = r._timer[other]
        until = run.until if timer is None or run.until < timer else timer
        if run.more and after < until:
            until = after  # the next message's first frame goes out then
        # every transfer in flight is a frame of the run on its way (b) or its ACK (c)
        events: list[tuple[float, int, int]] = []
        frames: dict[int, bytes] = {}  # frame k's bytes: on their way, or to be released
        for k in range(i0):
            b = s[k] + latency
            match = [x for x in transit if x[0] == b and x[2] == other]
            if match:
                # frame k by its header: the receiver's take judges its CRC (and declines it,
                # cutting the walk there, if it is bad), so it is not computed twice
                if len(match) > 1 or run.codec.data_header_num(match[0][3]) != nums[k]:
                    return
                frames[k] = match[0][3]
                events.append((b, 1, k))
            elif not any(x[0] == b + latency and x[2] == j and x[3] == acks[k]
                         for x in transit):
                return  # not ACKed at once (or lost): the ordinary calls
            events.append((b + latency, 2, k))
        for k in range(i0, n):
            sk = s[k]
            if sk >= until or sk > t_end:
                break
            b = sk + latency
            events += ((sk, 0, k), (b, 1, k), (b + latency, 2, k))
        events.sort()
        # what can happen, the receiver's choice apart
        walk: list[tuple[float, int, int]] = []
        received: list[int] = []
        released, acked, window, ack_timeout = i0, 0, run.window, run.ack_timeout
        last = len(events) - 1
        for e, event in enumerate(events):
            when, kind, k = event
            if when >= until or when > t_end or (e < last and events[e + 1][0] == when):
                break  # a deadline, the end of the run, or two events at one time
            if released > acked and s[acked] + ack_timeout <= when:
                break  # the oldest frame in flight times out first
            if kind == 0:
                if released - acked >= window:
                    break
                frames[k] = run.frame(k)
                released += 1
            elif kind == 1:
                received.append(k)
            else:
                acked += 1
            walk.append(event)
        if not walk:
            return
        asked, due = False, None  # the receiver's deadline, when it had to be asked again
        if received:  # consecutive frames
            first = received[0]
            got = take([frames[k] for k in received], [s[k] + latency for k in received],
                       acks[first:])
            if got < len(received):  # the receiver leaves that frame to the ordinary calls
                stop = first + got
                walk = walk[:next(e for e, (_, kind, k) in enumerate(walk)
                                  if kind == 1 and k == stop)]
                del received[got:]
                if not walk:
                    return
            if got and received[-1] == n - 1:
                # it took the message whole: what it did with it may have moved its deadline
                # (the ACKs still on their way back arrive only before that)
                asked, due = True, (self.n0, self.n1)[other].get_timer()
                if due is not None:
                    end = next(e for e, (_, kind, k) in enumerate(walk)
                               if kind == 1 and k == n - 1) + 1
                    while len(walk) > end and walk[-1][0] >= due:
                        walk.pop()
        # the transfers of the walked instants in their order (each takes the heap sequence
        # number its hand-over would); what was in flight and arrived leaves the heap, what
        # is still on its way goes into it
        seq = r._seq
        handed: list[tuple[int, float, bytes]] = []
        pending: dict[tuple[int, int], tuple[float, int, int, bytes]] = {}
        releases: list[float] = []
        ack_times: list[float] = []
        out_bytes = back_bytes = 0
        for when, kind, k in walk:
            if kind == 0:  # frame k released
                seq += 1
                frame = frames[k]
                handed.append((j, when, frame))
                pending[(1, k)] = (when + latency, seq, other, frame)
                releases.append(when)
                out_bytes += len(frame)
            elif kind == 1:  # frame k arrived, its ACK handed over
                if pending.pop((1, k), None) is None:
                    heapq.heappop(transit)  # it was in flight when the step began
                seq += 1
                ack = acks[k]
                handed.append((other, when, ack))
                pending[(2, k)] = (when + latency, seq, j, ack)
                back_bytes += len(ack)
            else:  # its ACK arrived
                ack_times.append(when)
                if pending.pop((2, k), None) is None:
                    heapq.heappop(transit)
        run_take(run, releases, ack_times)
        r._seq = seq
        for item in pending.values():
            heapq.heappush(transit, item)
        n_out, n_back = len(releases), len(handed) - len(releases)
        sent_stats, rcvd = (self.a0, self.a1)[j].stats, (self.a0, self.a1)[other].stats
        sent_stats.transfers_sent += n_out
        sent_stats.bytes_sent += out_bytes
        rcvd.transfers_received += n_out
        rcvd.bytes_received += out_bytes
        rcvd.transfers_sent += n_back
        rcvd.bytes_sent += back_bytes
        sent_stats.transfers_received += n_back
        sent_stats.bytes_received += back_bytes
        tap = r.tap
        if tap is not None:
            many = getattr(tap, "many", None)
            if many is not None:
                many(handed)
            else:
                for i, when, b in handed:
                    tap(i, when, b)
        now = r.now = walk[-1][0]
        self.instants += len(walk)
        self.handovers += 1
        self.sent_over[j] += 1
        self.handed += len(received)
        for i in (j, other):
            timer = due if i == other and asked else (self.n0, self.n1)[i].get_timer()
            if timer is not None and timer <= now:
                raise RuntimeError(f"node {i}: due at {now} after a handover")
            r._timer[i] = timer

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


def _hook(node: object, name: str) -> Callable[..., Any] | None:
    """A node's express hook, read from its own class only (not inherited, as SELF_CONTAINED:
    a subclass that rewrites what its node does must not be handed over past)."""
    return getattr(node, name, None) if name in vars(type(node)) else None


def _second(transit: list[tuple[float, int, int, bytes]]) -> float:
    """The arrival time of the second transfer in flight (a heap's second-smallest)."""
    if len(transit) == 2:
        return transit[1][0]
    return min(transit[1][0], transit[2][0])
