"""A new connection is a new EyeQ (decision L10): what the old connection left behind (frames
queued or in flight, a half-received transfer, transfers the adapter had not handed over) is
counted as the old connection's, never as an error of the new one, nor dropped silently."""

from __future__ import annotations

import socket
import time

import pytest

from eyeq_spi.emulator import build
from eyeq_spi.errors import LinkLostError
from eyeq_spi.host.host import HostEmulator
from eyeq_spi.host.machine import HostState
from eyeq_spi.phy.memory import memory_pair
from eyeq_spi.phy.stream import encode_transfer
from eyeq_spi.phy.tcp import TcpListenAdapter
from eyeq_spi.runner.virtual import VirtualRunner
from eyeq_spi.sim.eyeq import SimulatedEyeQ
from eyeq_spi.summary import LeftAtLinkLoss, RunningVision, host_summary, new_connection
from eyeq_spi.transport.segment import FIRST


def _cut_mid_transfer(host: HostEmulator, sim: SimulatedEyeQ, now: float) -> float:
    """Run the two by hand until the EyeQ sends the first frame of a multi-frame transfer;
    the host receives that frame and nothing after it (the EyeQ dies there). The host's own
    frames from then on are never ACKed. Returns the time reached."""
    while True:
        t = min(x for x in (sim.get_timer(), host.get_timer()) if x is not None)
        now = max(now, t)
        for node in (sim, host):
            if (timer := node.get_timer()) is not None and timer <= now:
                node.handle_timer(now)
        for frame in sim.data_to_send(now):
            host.receive_data(frame, now)
            if frame[6] == FIRST:
                host.handle_timer(now + 0.02)  # the host's next HOST_VEH_STATE is due
                host.data_to_send(now + 0.02)  # sent into the void: never ACKed
                return now + 0.02
        for frame in host.data_to_send(now):
            sim.receive_data(frame, now)


def test_a_new_connection_starts_clean_and_counts_what_the_old_one_left() -> None:
    emu = build()
    emu.run_for(2.0)
    host = emu.host
    assert host.state is HostState.RUNNING_VISION
    now = _cut_mid_transfer(host, emu.sim, emu.runner.now)
    left = LeftAtLinkLoss()
    # the new connection: a new EyeQ, powered up as the connection opens
    sim = SimulatedEyeQ()
    a, b = memory_pair()
    runner = VirtualRunner([(host, a), (sim, b)], start=now)
    sim.power_up(now)
    new_connection(host, now, left)
    vision = RunningVision()
    while runner.now < now + 3.0:
        runner.run_until(runner.now + 0.01)
        vision.update(host, runner.now)
    out = host_summary(host, side="host", elapsed=runner.now, wall=0.0, cpu=0.0,
                       running_since=vision.since, left_running=vision.left, connections=2,
                       left=left)
    assert out["left_at_link_loss"] == {"messages": 1, "transfers": 1}, out
    assert out["ok"], out["problem"]
    assert out["link"]["sendFailedErrorCounter"] == 0 and not out["transport_aborts"]
    assert out["e2e_errors"] == out["dasp_counter_gaps"] == 0


@pytest.mark.realtime
def test_a_listener_never_hands_a_new_peer_what_the_old_one_sent() -> None:
    listener = TcpListenAdapter(timeout=2.0)
    try:
        old = socket.create_connection(listener.address)
        old.sendall(encode_transfer(b"old 1") + encode_transfer(b"old 2"))
        assert listener.accept(2.0)
        assert listener.recv(2.0) == b"old 1"  # "old 2" is read and waits its turn
        old.close()
        deadline = time.monotonic() + 2.0
        with pytest.raises(LinkLostError):  # the peer's leaving shows on a write
            while time.monotonic() < deadline:
                listener.send(b"\x00" * 64)
                time.sleep(0.01)
        new = socket.create_connection(listener.address)
        new.sendall(encode_transfer(b"new 1"))
        assert listener.recv(2.0) == b"new 1"
        assert listener.stats.left_at_link_loss == 1
        new.close()
    finally:
        listener.close()


def _remote(seconds: float) -> tuple[HostEmulator, SimulatedEyeQ, RunningVision]:
    """A host and an EyeQ as ``host`` and ``sim`` run them: no reset line between them."""
    host, sim = HostEmulator(), SimulatedEyeQ()
    a, b = memory_pair()
    runner = VirtualRunner([(host, a), (sim, b)])
    sim.power_up(0.0)
    host.start(0.0)
    vision = RunningVision()
    while runner.now < seconds:
        runner.run_until(runner.now + 0.01)
        vision.update(host, runner.now)
    return host, sim, vision


def test_a_first_connection_has_no_resynchronisation() -> None:
    """The empty NVM's soft reset (Switch EyeQ Application, L10): the EyeQ's link restarts
    because the host asked; that is the reset, counted as asked, not a resynchronisation."""
    host, _, vision = _remote(2.0)
    out = host_summary(host, side="host", elapsed=2.0, wall=0.0, cpu=0.0,
                       running_since=vision.since, left_running=vision.left)
    assert out["ok"], out["problem"]
    assert out["link"]["resynchronisations"] == 0, out["link"]
    assert out["eyeq_reset_causes"] == {"asked_by_host": 1, "not_asked": 0}


def test_the_sim_says_when_a_host_went_away_and_what_it_left() -> None:
    from eyeq_spi.summary import SimSessions, format_summary, sim_summary

    _, sim, _ = _remote(2.0)
    sim.conn.send(bytes(300), 2.0)  # a message the host will never ACK: it vanished
    sim.data_to_send(2.0)
    served = SimSessions()
    served.add(sim, began=0.0, ended=2.0, link_lost="peer of tcp://x went away")
    text = format_summary(sim_summary(sim, served.sessions, elapsed=3.0, wall=3.0, cpu=0.0))
    assert "the host went away at 2.00 s" in text and "mid-session" in text, text
    assert "not ACKed" in text, text
