"""Decision L10: a reset starts both link directions afresh. The link's learning restart, the
host and the simulated EyeQ around a Switch EyeQ Application and a boot status that repeats the
last one byte for byte, and the dissector (engine and batch path agree). Virtual time."""

from __future__ import annotations

from eyeq_spi.capture.pcapng_fast import chunks_from_transfers
from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect import engine
from eyeq_spi.dissect import engine_fast as batch
from eyeq_spi.host.host import HostConfig, HostEmulator
from eyeq_spi.host.machine import HostState
from eyeq_spi.link.connection import LinkConfig, LinkConnection
from eyeq_spi.link.events import DataReceived, DuplicateReceived, Resynchronised
from eyeq_spi.link.frame import FrameCodec
from eyeq_spi.phy.memory import memory_pair
from eyeq_spi.runner.virtual import VirtualRunner
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.sim.eyeq import SimulatedEyeQ
from tests.test_dissect_engine_fast import Wire

FC = FrameCodec()
MC = MessageCodec()
BOOT = FC.data_frame(0, 0, b"\x00\x20\x10\x00\x02")  # a boot status at NUM 0, RSP 0


def _events(link: LinkConnection) -> list[object]:
    out: list[object] = []
    while (ev := link.next_event()) is not None:
        out.append(ev)
    return out


def test_a_byte_identical_boot_status_after_a_reset_is_not_a_duplicate() -> None:
    rx = LinkConnection(LinkConfig(role="host"))
    rx.receive_data(BOOT, 0.0)
    assert any(isinstance(e, DataReceived) for e in _events(rx))
    rx.receive_data(BOOT, 0.1)  # without a reset: L6a's duplicate
    assert any(isinstance(e, DuplicateReceived) for e in _events(rx))
    rx.restart()  # L10: the EyeQ reset; the same bytes again are a new frame
    rx.receive_data(BOOT, 0.2)
    assert [type(e) for e in _events(rx)] == [DataReceived]


def test_a_learning_receiver_skips_frames_in_flight_from_before_the_reset() -> None:
    """After ``reset(learn=True)`` frames the peer sent before its reset may still arrive; its
    first frame after (NUM 0, RSP 0) takes E back to 0 without a NAK."""
    rx = LinkConnection(LinkConfig(role="host"))
    rx.reset(learn=True)
    for num in (41, 42):
        rx.receive_data(FC.data_frame(7, num, b"\x00\x01\x41"), 0.0)
    rx.receive_data(BOOT, 0.01)
    evs = _events(rx)
    assert any(isinstance(e, Resynchronised) and e.cause == "peer_restart" for e in evs)
    assert rx.counters.naksSent == {} and rx.expected_num == 1


def test_frames_after_a_reset_request_are_numbered_from_0() -> None:
    tx = LinkConnection(LinkConfig(role="host", frame_gap=0.0))
    tx.send(b"\x00\x01\x01", 1, 0.0)
    tx.send(b"\x00\x01\x02", 2, 0.0)  # the Switch EyeQ Application request
    tx.restart_after(2, 0.0)
    tx.send(b"\x00\x01\x03", 3, 0.0)
    nums = [FC.decode(t).num for t in tx.data_to_send(0.0)]
    assert nums == [0, 1, 0]


def _state(host: HostEmulator) -> HostState:
    return host.state


def _pair(cfg: SimConfig, host_cfg: HostConfig | None = None, *, reset_line: bool = True
          ) -> tuple[SimulatedEyeQ, HostEmulator, VirtualRunner]:
    sim = SimulatedEyeQ(cfg)
    host = HostEmulator(host_cfg, reset_line=sim.power_up if reset_line else None)
    a, b = memory_pair()
    runner = VirtualRunner([(host, a), (sim, b)])
    sim.power_up(0.0)
    host.start(0.0)
    return sim, host, runner


def test_soft_reset_reboots_a_failing_eyeq_and_the_host_reaches_vision() -> None:
    """No reset line (a remote EyeQ): Switch EyeQ Application while the EyeQ failed its boot
    boots it again (a new boot status, counted against ``boot_failures``); both links start
    afresh (L10), so its two identical failing boot statuses are both seen."""
    sim, host, runner = _pair(SimConfig(objects=1, signs=1, light_spots=1, boot_failures=2,
                                        boot_test_failures=0x0002), reset_line=False)
    runner.run_until(4.0)
    assert sim.counters.boots == 3
    assert host.counters.boot_failures == 2
    assert host.state is HostState.RUNNING_VISION, host.transitions[-4:]
    assert host.conn.link.counters.naksSent == {}


def test_mode_switch_restarts_both_links_without_a_nak() -> None:
    """A TAC round trip: each accepted Switch EyeQ Application restarts both directions (L10);
    the host's NUMs start over after its request, the EyeQ's reply is its NUM 0."""
    sim, host, runner = _pair(SimConfig(objects=1, signs=1, light_spots=1, tac_duration=0.3))
    runner.run_until(2.0)
    assert host.state is HostState.RUNNING_VISION
    before = host.conn.link.next_num
    host.switch_mode("TAC", runner.now)
    runner.run_until(runner.now + 1.5)
    assert _state(host) is HostState.RUNNING_TAC
    assert host.conn.link.next_num < before
    host.switch_mode("VISION", runner.now)
    runner.run_until(runner.now + 2.0)
    assert _state(host) is HostState.RUNNING_VISION
    for link in (host.conn.link, sim.conn.link):
        assert link.counters.naksSent == {}, link.counters
        assert link.counters.sequenceErrorCounter == 0


def _switch_capture() -> list[Transfer]:
    """HOST_VEH_STATE_MSG both ways of a Switch EyeQ Application; after it the host numbers its
    frames from 0 (RSP not 0: it has accepted EyeQ frames), and the EyeQ's reply is its NUM 0."""
    wire = Wire()
    zero = MC.layout(MC.message("HOST_VEH_STATE_MSG")).zero_values()
    e2e = E2EState()
    for k in range(2):
        for i in range(20):
            wire.send("h2e", MC.encode_dasp("HOST_VEH_STATE_MSG", zero, 20 * k + i, e2e))
            wire.t += 0.015
        if k == 0:
            wire.send("h2e", MC.mesp.encode_request("SwitchEyeQApplication", 7,
                                                    {"applicationId": 1}))
            wire.num["h2e"] = wire.num["e2h"] = 0
            wire.send("e2h", MC.mesp.encode_reply("SwitchEyeQApplication", 7, 0,
                                                  {"applicationId": 1}))
            e2e = E2EState()
    return [Transfer(t, d, w) for d, t, w in wire.out]


def test_the_dissector_follows_a_reset_request_in_both_paths() -> None:
    recs = _switch_capture()
    out = list(engine.iter_records(recs))
    rejected = [r for r in out if r.get("type") == "frame_rejected"]
    assert not rejected, rejected[:2]
    assert sum(r.get("name") == "HOST_VEH_STATE_MSG" for r in out) == 40
    resets = [r for r in out if r.get("type") == "driver_reset"]
    assert [r["direction"] for r in resets] == ["h2e"]  # the host's NUM 0 after its request
    for chunk in (5, 64, 1 << 15):
        assert list(batch.iter_records(chunks_from_transfers(recs, chunk))) == out


def test_after_an_eyeq_reset_the_restarted_host_link_is_taken_at_once() -> None:
    """The EyeQ resets by itself under a host without a reset line: the host learns of it late
    (three NAKs, L6) and then numbers from 0 (L10); the EyeQ, which had learnt the host's old
    numbering, takes that NUM 0 as the host's restart instead of NAKing the host's bring-up
    requests, so the bring-up is not held up by MESP retries."""
    sim, host, runner = _pair(SimConfig(objects=1, signs=1, light_spots=1,
                                        app_start_delay=0.3), reset_line=False)
    runner.run_until(2.0)
    assert host.state is HostState.RUNNING_VISION
    t0 = runner.now
    sim.power_up(t0)
    runner.run_until(t0 + 0.3)
    while runner.now < t0 + 5.0 and not (
            _state(host) is HostState.RUNNING_VISION and sim.main_state == 0x02):
        runner.run_until(runner.now + 0.01)
    assert runner.now - t0 < 1.0
    assert sim.conn.link.counters.naksSent == {}
