"""Express instants (runner/virtual_fast.py) give the same transfers at the same virtual times, and
leave host, simulated EyeQ and link in the same state, as the general per-frame loop (the
reference, ``express=False`` or ``EYEQ_SPI_EXACT=1``): on clean runs and on the faults and
resets the emulator can inject."""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any

import pytest

from eyeq_spi.emulator import HOST_ALONE, Emulation, build
from eyeq_spi.host.machine import HostState
from eyeq_spi.link.frame import FrameCodec, FrameKind
from eyeq_spi.phy.memory import MemoryAdapter
from eyeq_spi.runner.virtual import VirtualRunner
from eyeq_spi.runner.virtual_fast import Express
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.twins import EXACT_ENV

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

Trace = list[tuple[int, float, bytes]]


def _emulation(express: bool, cfg: SimConfig, **runner: Any) -> tuple[Emulation, Trace]:
    trace: Trace = []
    emu = build(sim_config=cfg, keep_rx_times=False)
    emu.runner = VirtualRunner(emu.runner.nodes, tap=lambda i, t, b: trace.append((i, t, b)),
                               self_contained=HOST_ALONE, express=express, **runner)
    return emu, trace


def _layers(node: Any) -> tuple[Any, ...]:
    """A node's link and transport down to the times and frames they keep: what a handover
    that got a time, a NUM or a frame wrong would leave different even where the wire does
    not show it yet."""
    conn = node.conn
    link, o = conn.link, conn._open
    return (node.now, node.get_timer(), link.next_num, link.expected_num, link._last_accepted,
            link._next_tx, link._next_ctl, link._naks_in_row, list(link._inflight.items()),
            link._expect_restart_frames, link._expect_restart_until,
            [(q.tag, q.deadline, q.data) for q in link._queue], list(link._accepted.items()),
            {k: list(v) for k, v in link._tags.items()}, list(link._control),
            None if o is None else (o.transfer_id, o.total, bytes(o.buf), o.last_num,
                                    o.deadline, o.nums), conn._dead_id)


def _state(emu: Emulation) -> dict[str, Any]:
    """What both paths must agree on besides the wire: counters of every layer, the host's
    state machine history, the adapters' statistics, the clock."""
    host, sim = emu.host, emu.sim
    return {
        "now": emu.runner.now,
        "host_state": host.state,
        "transitions": list(host.transitions),
        # what the host keeps of the messages it took: E2E and DASP counters, stale streams
        "host_rx": (dict(host._last_rx), sorted(host._stale), dict(host._e2e.seen),
                    dict(host._rx_counters._last), host.last_diag),
        "host_counters": repr(host.counters),
        "sim_counters": repr(sim.counters),
        "links": [repr(n.conn.link.counters) for n in (host, sim)],
        "ack_latency": [dict(n.conn.link.ack_latency) for n in (host, sim)],
        "transport": [repr(n.conn.counters) for n in (host, sim)],
        "adapters": [repr(a.stats) for _, a in emu.runner.nodes],
        "layers": [_layers(n) for n in (host, sim)],
        "in_flight": sorted(emu.runner._transit),
        "seq": emu.runner._seq,
    }


CASES = {
    "full_load": (SimConfig(objects=15, signs=20, light_spots=15), 3.0),
    "eyeq_resets_itself": (SimConfig(reset_at=1.2), 2.5),
    "boot_failures_reset_line": (SimConfig(boot_test_failures=1, boot_failures=2), 2.5),
    "late_and_dropped_replies": (
        SimConfig(reply_delay=0.03, drop_replies={"GetEyeQExtendedState": 2}), 2.0),
}


def _first_difference(old: Trace, new: Trace) -> str | None:
    k = next((k for k, (a, b) in enumerate(zip(old, new, strict=False)) if a != b), None)
    if k is None:
        return None if len(old) == len(new) else f"lengths {len(old)} and {len(new)}"
    return f"transfer {k}: {old[k][:2]} {old[k][2][:8].hex()} / {new[k][:2]} {new[k][2][:8].hex()}"


def _lockstep(cfg: SimConfig, seconds: float, window: int | None = None, slice_s: float = 0.0007,
              min_transfers: int = 1000, setup: Callable[[Emulation], None] | None = None,
              driven: bool = True, **runner: Any) -> tuple[Emulation, Trace]:
    """Run the reference and the express path side by side in slices of 0.7 ms (which end
    inside messages, where a handover stops with frames and ACKs still on their way), and
    compare the transfers so far and the state of every layer after each slice. Returns the
    express run and its transfers. (A longer ``slice_s`` lets a handover run on to the
    nodes' own deadlines.) ``driven=False``: the express run's slices keep the runner's
    caches, as the emulator's own slices do."""
    pair = []
    for express in (False, True):
        emu, trace = _emulation(express, SimConfig(**vars(cfg)), **runner)
        if window is not None:
            emu.sim.conn.link.config.window = window
        if setup is not None:
            setup(emu)
        pair.append((emu, trace))
    (ref, ref_trace), (fast, fast_trace) = pair
    t = 0.0
    while t < seconds:
        t += slice_s
        ref.runner.run_until(t)
        fast.runner.run_until(t, driven=driven or t == slice_s)
        assert _first_difference(ref_trace, fast_trace) is None, \
            f"at {t}: {_first_difference(ref_trace, fast_trace)}"
        assert _state(ref) == _state(fast), f"at {t}"
    assert len(ref_trace) > min_transfers
    assert ref.runner._express is None
    return fast, fast_trace


@pytest.mark.parametrize("case", list(CASES))
def test_express_gives_the_reference_transfers_and_state(case: str) -> None:
    cfg, seconds = CASES[case]
    fast, fast_trace = _lockstep(cfg, seconds)
    loop = fast.runner._express
    assert loop is not None and loop.instants > 0.8 * len({t for _, t, _ in fast_trace})
    if case == "full_load":  # most DATA frames continue a message: the host takes them in one
        # step, most of them in the handover of the rest of their message
        codec = FrameCodec()
        data = sum(1 for i, _, b in fast_trace if i == 1 and codec.judge(b)[0] == FrameKind.DATA)
        assert loop.absorbed + loop.handed > 0.5 * data
        assert loop.handed > 0.5 * data


@pytest.mark.parametrize("case", list(CASES))
def test_slices_that_keep_the_caches_give_the_reference(case: str) -> None:
    """``run_until(driven=False)`` (nothing drove a node since the last call) goes on from
    the caches the last call left, with no round of the general loop at the start: the same
    transfers and state as the reference, which starts every slice afresh."""
    cfg, seconds = CASES[case]
    _lockstep(cfg, seconds, driven=False)


def test_emulator_slices_keep_the_runner_caches(monkeypatch: pytest.MonkeyPatch) -> None:
    """Emulation.run_for runs 10 ms slices: only its first starts afresh (the others follow
    slices in which only the host's state was read); with a ``stop`` condition, every one."""
    monkeypatch.delenv(EXACT_ENV, raising=False)
    emu = build(keep_rx_times=False)
    emu.run_for(1.0)
    touched = []
    monkeypatch.setattr(emu.runner, "touch_all", lambda: touched.append(emu.runner.now))
    emu.run_for(0.5)
    assert touched == [pytest.approx(1.0)]
    touched.clear()
    emu.run_for(0.1, stop=lambda: False)
    assert len(touched) == 10  # each slice starts afresh


def test_host_takes_whole_messages_and_its_last_acks_in_one_step() -> None:
    """In Running Vision, with nobody subscribed, the frame that completes a DASP message, the
    ACK of the host's own message's last frame, and a 0x41 that starts no state event
    (``HostEmulator._quiet``) are taken whole (``HostEmulator.express_absorb`` and the
    handover): at full load no transfer reaches the host's ordinary ``receive_data``. (That both
    give the same transfers and state is the lockstep test above.)"""
    emu, _ = _emulation(True, SimConfig(objects=15, signs=20, light_spots=15))
    emu.run_for(2.0)
    calls: list[bytes] = []
    ordinary = emu.host.receive_data

    def receive_data(transfer: bytes, now: float) -> None:
        calls.append(transfer)
        ordinary(transfer, now)

    emu.host.receive_data = receive_data  # type: ignore[method-assign]
    before = emu.host.conn.counters.messagesReceived
    diag = emu.host.counters.received["EYEQ_DIAGNOSTIC_MSG"]
    emu.run_for(1.0)
    assert emu.host.conn.counters.messagesReceived - before > 200
    assert emu.host.counters.received["EYEQ_DIAGNOSTIC_MSG"] - diag > 20
    assert len(calls) <= 2


@pytest.mark.parametrize("event", ["fatal", "went_back"])
def test_a_0x41_that_starts_an_event_takes_the_ordinary_calls(event: str) -> None:
    """A 0x41 in Running Vision that reports a fatal error (the host goes to FATAL) or a
    Main_State gone back to Pending (the host takes it for a reset of the EyeQ and pulls its
    reset line, which acts on the other node): the express paths leave it to
    ``receive_data``, and both paths give the same transfers and state."""
    from eyeq_spi.sim.mesp_functions import PENDING

    traces, states = [], []
    for express in (False, True):
        emu, trace = _emulation(express, SimConfig(objects=15))
        emu.run_for(1.5)
        assert emu.host.state is HostState.RUNNING_VISION
        if event == "fatal":
            emu.sim.config.fatal_error = 7
        else:
            emu.sim.main_state = PENDING
        emu.run_for(0.5)
        assert emu.host.state is not HostState.RUNNING_VISION or emu.host.counters.eyeq_resets
        traces.append(trace)
        states.append(_state(emu))
    assert _first_difference(traces[0], traces[1]) is None
    assert states[0] == states[1]


HANDOVER_CASES: dict[str, tuple[dict[str, Any], dict[str, Any], int | None]] = {
    # (SimConfig fields, VirtualRunner arguments, the EyeQ's window)
    # an ACK comes back before the next frame goes out: one frame in flight at a time
    "short_wire": ({}, {"latency": 40e-6}, None),
    # an arrival lands exactly on a release (two events at one time: the general loop)
    "arrival_on_a_release": ({}, {"latency": 100e-6}, None),
    # the next frame goes out before the last one arrives
    "long_wire": ({}, {"latency": 450e-6}, None),
    # messages queued back to back, the next one's first frame due while ACKs are on their way
    "messages_back_to_back": ({"dasp_rate": 40}, {"latency": 450e-6}, None),
    # the window fills: the EyeQ waits for an ACK before each frame
    "window_of_one": ({}, {}, 1),
    # an ackTimeout just above the round trip; the frames of the longer messages dropped by
    # their transmit timeout in the middle of the message
    "timeouts_inside_messages": ({"ack_timeout": 210e-6, "transmit_timeout": 1.5e-3}, {},
                                 None),
}


@pytest.mark.parametrize("case", list(HANDOVER_CASES))
def test_handover_gives_the_reference_transfers_and_state(case: str) -> None:
    """The handover of a message's rest stops where the per-frame loop would do something
    else: two events at one time, a full window, a timeout inside the message; and its times
    follow the wire's latency either side of the frame gap. Compared slice by slice."""
    fields, runner, window = HANDOVER_CASES[case]
    fast, _ = _lockstep(SimConfig(objects=15, signs=20, light_spots=15, **fields), 1.2, window,
                        **runner)
    loop = fast.runner._express
    assert loop is not None and loop.handed > 0


def test_host_messages_handed_over_up_to_the_host_deadlines() -> None:
    """The host's own messages are handed over too (HostEmulator.express_run, the EyeQ's
    express_take), up to the host's own deadlines: on a wire with a 6 ms round trip to an
    EyeQ that rarely sends, its 10 ms stale check and its next HOST_VEH_STATE_MSG fall
    inside the handover of its messages. Compared in slices longer than a round trip."""
    fast, _ = _lockstep(SimConfig(dasp_rate=2.0, diag_rate=2.0), 3.0, slice_s=0.0113,
                        min_transfers=300, latency=3e-3)
    loop = fast.runner._express
    assert loop is not None and loop.sent_over[0] > 20


def test_link_restart_then_handover() -> None:
    """L10 in a whole emulation: the EyeQ resets by itself and the host, with no reset line,
    restarts its link (``TransportConnection.restart``: numbering from 0, the next DATA
    frame sets E, a NUM 0 frame within the restart horizon may be the peer's restart), brings
    the EyeQ up again and takes its messages in handovers once more. Compared slice by
    slice."""
    restarts: list[tuple[float, int]] = []

    def no_reset_line(emu: Emulation) -> None:
        emu.host.reset_line = None
        restart = emu.host.conn.restart

        def recorded() -> None:
            loop = emu.runner._express
            restarts.append((emu.host.now, 0 if loop is None else loop.handovers))
            restart()

        emu.host.conn.restart = recorded  # type: ignore[method-assign]

    fast, _ = _lockstep(SimConfig(objects=15, signs=20, light_spots=15, reset_at=1.2), 2.6,
                        setup=no_reset_line)
    host, loop = fast.host, fast.runner._express
    assert host.counters.eyeq_resets >= 1 and host.state is HostState.RUNNING_VISION
    assert loop is not None
    at, before = restarts[-1]  # the express run's (the reference's come first)
    assert 1.2 <= at < 2.0 and loop.handovers > before + 100


def test_mode_switch_from_outside_between_runs() -> None:
    traces, states = [], []
    for express in (False, True):
        emu, trace = _emulation(express, SimConfig(objects=15))
        emu.run_for(1.5)
        assert emu.host.state is HostState.RUNNING_VISION
        emu.host.switch_mode("DV", emu.runner.now)
        emu.run_for(1.0)
        traces.append(trace)
        states.append(_state(emu))
    assert _first_difference(traces[0], traces[1]) is None
    assert states[0] == states[1]


def test_faulty_wire_runs_the_reference_loop() -> None:
    """A fault hook on the wire (drops, duplicates, bad CRCs): no express instant at all, so the
    run is the reference's by construction."""
    emu, trace = _emulation(True, SimConfig())
    rng = random.Random(3)

    def mangle(t: bytes) -> list[bytes]:
        r = rng.random()
        return [] if r < 0.02 else [t, t] if r < 0.04 else [t]

    for _, adapter in emu.runner.nodes:
        assert isinstance(adapter, MemoryAdapter)
        adapter.mangle = mangle
    emu.run_for(1.0)
    assert len(trace) > 100
    assert emu.runner._express is not None and emu.runner._express.instants == 0


def test_exact_switch_and_verify_turn_express_off(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(EXACT_ENV, "1")
    emu = build(sim_config=SimConfig())
    assert emu.runner.express is False
    emu.run_for(0.2)
    assert emu.runner._express is None
    monkeypatch.setenv(EXACT_ENV, "0")
    emu = build(sim_config=SimConfig())
    assert emu.runner.express is True
    emu.runner.verify = True
    emu.run_for(0.2)
    assert emu.runner._express is None


def test_express_needs_two_self_contained_nodes_on_one_pair() -> None:
    from eyeq_spi.conformance.mutants import NoAck
    from eyeq_spi.sim.eyeq import SimulatedEyeQ

    a, b = MemoryAdapter(), MemoryAdapter()
    a.peer, b.peer = b, a
    assert not Express.eligible(VirtualRunner([(SimulatedEyeQ(), a), (NoAck(), b)]))
    assert Express.eligible(VirtualRunner([(SimulatedEyeQ(), a), (SimulatedEyeQ(), b)]))
    assert not Express.eligible(VirtualRunner([(SimulatedEyeQ(), a), (SimulatedEyeQ(), b)],
                                              latency=0.0))


def _ordinary(rx: Any, frame: bytes, t: float) -> list[bytes]:
    """What a runner does with a frame: receive_data, handle_timer if due, data_to_send."""
    rx.receive_data(frame, t)
    timer = rx.get_timer()
    if timer is not None and timer <= t:
        rx.handle_timer(t)
    out: list[bytes] = rx.data_to_send(t)
    return out


def _snapshot(rx: Any) -> tuple[Any, ...]:
    link, o = rx.link, rx._open
    events = []
    while (ev := rx.next_event()) is not None:
        events.append(ev)
    return (repr(link.counters), link.expected_num, list(link._accepted.items()),
            link._next_ctl, link._naks_in_row, link._started, link._expect_restart_frames,
            link._expect_restart_until, repr(rx.counters), rx._dead_id, rx._seen_first,
            None if o is None else (o.transfer_id, o.total, bytes(o.buf), o.last_num, o.deadline,
                                    o.nums), events, rx.get_timer())


def _sender_snapshot(tx: Any) -> tuple[Any, ...]:
    link = tx.link
    events = []
    while (ev := tx.next_event()) is not None:
        events.append(ev)
    return (repr(link.counters), dict(link.ack_latency), list(link._inflight.items()),
            {k: list(v) for k, v in link._tags.items()}, link.next_num, link.queued,
            repr(tx.counters), events, tx.get_timer())


@pytest.mark.parametrize("seed", range(6))
def test_absorb_is_receive_timer_and_send_in_one_step(seed: int) -> None:
    """The transport's express hooks against the ordinary calls, frame by frame, on a stream
    with every fault the link knows: drops, duplicates, bad CRCs, swapped frames, a sender that
    starts over, a silence longer than the reassembly timeout; on the receiver (DATA frames)
    and on the sender (their ACKs). Where a hook declines it must have changed nothing (the
    ordinary path then gives the same result)."""
    from eyeq_spi.link.connection import LinkConfig
    from eyeq_spi.transport.connection import TransportConnection

    rng = random.Random(seed)
    # the senders never wait for an ACK, so that ACKs come late, twice or never
    tx_fast, tx_ref = (TransportConnection(LinkConfig(role="eyeq", window=1000))
                       for _ in range(2))
    fast, ref = (TransportConnection(LinkConfig(role="host")) for _ in range(2))
    t, absorbed, declined, acks = 0.0, 0, 0, 0
    for _ in range(300):
        if rng.random() < 0.03:
            tx_fast.reset()  # the EyeQ starts over: same NUMs, other bytes (L6a)
            tx_ref.reset()
        message = rng.randbytes(rng.choice([5, 117, 300, 700, 1500]))
        tx_fast.send(message, t)
        tx_ref.send(message, t)
        frames: list[bytes] = []
        while tx_ref.link.queued:
            t += 0.0002
            frames += tx_ref.data_to_send(t)
            assert tx_fast.data_to_send(t) == frames[-1:]
        for k, frame in enumerate(list(frames)):
            r = rng.random()
            if r < 0.04:
                frames[k] = frame[:-1] + bytes([frame[-1] ^ 1])  # bad CRC
            elif r < 0.07:
                frames[k] = b""  # dropped
            elif r < 0.10:
                frames.append(frame)  # duplicated later
            elif r < 0.12 and k + 1 < len(frames):
                frames[k], frames[k + 1] = frames[k + 1], frame  # swapped
        for frame in frames:
            if not frame:
                continue
            t += 0.0003 if rng.random() > 0.02 else 0.03  # now and then a long silence
            ack = fast.absorb(frame, t)
            if ack is None:
                declined += 1
                got = _ordinary(fast, frame, t)
            else:
                absorbed += 1
                got = [ack]
            assert got == _ordinary(ref, frame, t)
            assert _snapshot(fast) == _snapshot(ref)
            for back in got:
                if rng.random() < 0.05:
                    continue  # the ACK is lost
                t += 0.0001
                if tx_fast.absorb_ack(back, t):
                    acks += 1
                    assert tx_fast.data_to_send(t) == []
                    assert _ordinary(tx_ref, back, t) == []
                else:
                    assert _ordinary(tx_fast, back, t) == _ordinary(tx_ref, back, t)
                assert _sender_snapshot(tx_fast) == _sender_snapshot(tx_ref)
    assert absorbed > 200 and declined > 200 and acks > 100


@pytest.mark.parametrize("seed", range(4))
def test_absorb_run_is_absorb_frame_after_frame(seed: int) -> None:
    """The receiver's side of a handover (TransportConnection.absorb_run) takes what the
    ordinary calls take at once, frame after frame, and stops at the first frame they would
    treat otherwise: on runs cut from streams with drops, duplicates, bad CRCs, swapped
    frames, a sender that starts over, a receiver that restarts its link (L10: both directions
    afresh, a NUM 0 frame may be the peer's restart), silences longer than the reassembly
    timeout, and ACKs that the sender would not take as its own (another codec)."""
    from eyeq_spi.crc import VARIANTS
    from eyeq_spi.link.connection import LinkConfig
    from eyeq_spi.link.frame import SEQ_MODULO
    from eyeq_spi.transport.connection import TransportConnection

    rng = random.Random(seed)
    tx = TransportConnection(LinkConfig(role="eyeq", window=1000))
    fast, ref = (TransportConnection(LinkConfig(role="host")) for _ in range(2))
    other = FrameCodec(crc=VARIANTS["CRC-16/KERMIT"])
    t, taken, stopped = 0.0, 0, 0
    for _ in range(150):
        if rng.random() < 0.03 or tx.link.in_flight > 900:  # (it never hears an ACK)
            tx.reset()  # the sender starts over
        if rng.random() < 0.05:  # L10 on the receiving side, with the sender numbering anew
            tx.reset()
            for rx in (fast, ref):
                rx.link.restart()
        tx.send(rng.randbytes(rng.choice([5, 300, 476, 700, 1500, 2684])), t)
        frames: list[bytes] = []
        while tx.link.queued:
            t += 0.0002
            frames += tx.data_to_send(t)
        for k, frame in enumerate(list(frames)):
            r = rng.random()
            if r < 0.02:
                frames[k] = frame[:-1] + bytes([frame[-1] ^ 1])
            elif r < 0.04:
                frames[k] = b""
            elif r < 0.06:
                frames.append(frame)
            elif r < 0.07 and k + 1 < len(frames):
                frames[k], frames[k + 1] = frames[k + 1], frame
        frames = [f for f in frames if f]
        i = 0
        while i < len(frames):
            run = frames[i:i + rng.randint(1, 12)]
            times = []
            for _ in run:
                t += 0.0003 if rng.random() > 0.01 else 0.03
                times.append(t)
            e = fast.link.expected_num
            codec = other if rng.random() < 0.05 else fast.link.codec
            acks = None if rng.random() < 0.3 else [codec.ack((e + k) % SEQ_MODULO)
                                                     for k in range(len(run))]
            n = fast.absorb_run(run, times, acks)
            for k in range(n):  # taken: each is what the ordinary calls do with it
                ack = fast.link.codec.ack((e + k) % SEQ_MODULO)
                assert _ordinary(ref, run[k], times[k]) == [ack]
                assert acks is None or acks[k] == ack
            assert _snapshot(fast) == _snapshot(ref)
            taken += n
            if n < len(run):  # the first it left: the ordinary calls, on both
                stopped += 1
                assert _ordinary(fast, run[n], times[n]) == _ordinary(ref, run[n], times[n])
                assert _snapshot(fast) == _snapshot(ref)
                n += 1
            i += n
    assert taken > 500 and stopped > 100


def test_absorb_run_leaves_num_0_in_the_restart_horizon_to_receive_data() -> None:
    """After a restart of its link (L10) a receiver that has learnt E from the peer's frames
    still takes a NUM 0 frame for the peer's possible restart until the horizon has passed:
    where the peer's numbering wraps to 0 just then, absorb_run leaves that frame to the
    ordinary calls (which end the horizon)."""
    from eyeq_spi.link.connection import LinkConfig
    from eyeq_spi.transport.connection import TransportConnection

    tx = TransportConnection(LinkConfig(role="eyeq", window=1000))
    tx.reset(tx_num=4090)
    fast, ref = (TransportConnection(LinkConfig(role="host")) for _ in range(2))
    for rx in (fast, ref):
        rx.link.restart()
    t = 0.0
    tx.send(bytes(range(256)) * 6, t)  # 13 frames: NUM 4090..4095, 0..6
    frames: list[bytes] = []
    while tx.link.queued:
        t += 0.0002
        frames += tx.data_to_send(t)
    times = [0.01 + 0.0003 * k for k in range(len(frames))]
    for rx in (fast, ref):  # the first frame sets E (the ordinary calls)
        _ordinary(rx, frames[0], times[0])
    assert fast.absorb_run(frames[1:], times[1:]) == 5  # up to NUM 4095
    for k in range(1, 6):
        _ordinary(ref, frames[k], times[k])
    assert _snapshot(fast) == _snapshot(ref)
    assert fast.link._expect_restart_frames > 0
    for k in range(6, len(frames)):  # NUM 0, then the rest
        assert _ordinary(fast, frames[k], times[k]) == _ordinary(ref, frames[k], times[k])
    assert _snapshot(fast) == _snapshot(ref) and fast.link._expect_restart_frames == 0


def test_a_tap_with_a_block_method_gets_the_handover_in_blocks() -> None:
    """A tap that offers ``many(transfers)`` gets a handover's transfers in one call, the
    others one by one: together every transfer, in order, with its time, as a plain tap."""

    class BlockTap:
        def __init__(self) -> None:
            self.trace: Trace = []
            self.blocks = 0

        def __call__(self, i: int, t: float, b: bytes) -> None:
            self.trace.append((i, t, b))

        def many(self, transfers: list[tuple[int, float, bytes]]) -> None:
            self.blocks += 1
            self.trace.extend(transfers)

    cfg = SimConfig(objects=15, signs=20, light_spots=15)
    ref, ref_trace = _emulation(False, cfg)
    ref.run_for(1.5)
    tap = BlockTap()
    emu = build(sim_config=SimConfig(**vars(cfg)), keep_rx_times=False)
    emu.runner = VirtualRunner(emu.runner.nodes, tap=tap, self_contained=HOST_ALONE,
                               express=True)
    emu.run_for(1.5)
    assert tap.blocks > 10
    assert _first_difference(ref_trace, tap.trace) is None
