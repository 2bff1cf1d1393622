"""Lossy-channel soak: host and simulated EyeQ through the memory pair's fault
hook, in virtual time. Every injected fault is accounted for by the receiver's counters (exact
where the rule is deterministic, see ``eyeq_spi.faults.soak``), no corrupted message is ever
delivered, and Running Vision is reached and held under loss."""

from __future__ import annotations

import math

import pytest

from eyeq_spi.errors import UsageError
from eyeq_spi.faults.channel import KINDS, FaultProfile, FaultyChannel
from eyeq_spi.faults.soak import EXACT, SoakConfig, SoakReport, run_soak
from eyeq_spi.link.frame import FrameCodec


@pytest.fixture(scope="module")
def soak() -> SoakReport:
    # The default fault profile (BER 1e-5, 1% each of drop, duplicate, reorder, truncation),
    # switched on in Running Vision so that the bring-up's reset-free path keeps the accounting
    # exact.
    return run_soak(SoakConfig(duration=6.0, seed=1))


def test_soak_injects_every_fault_class_in_both_directions(soak: SoakReport) -> None:
    for side, acc in soak.accounting.items():
        for kind in KINDS:
            assert acc.injected.get(kind, 0) >= 20, (side, kind, acc.injected)
    assert soak.frames["eyeq_to_host"] > 5000 and soak.frames["host_to_eyeq"] > 5000


def test_no_corrupted_message_is_delivered_and_vision_holds(soak: SoakReport) -> None:
    assert soak.corrupted == 0, soak.messages
    for figures in soak.messages.values():
        assert figures["delivered"] > 0.8 * figures["sent"]
    assert soak.held and soak.final_state == "RUNNING_VISION", soak.host


@pytest.mark.parametrize("side", ["eyeq", "host"])
def test_receiver_counters_account_for_every_injected_fault(soak: SoakReport, side: str) -> None:
    acc = soak.accounting[side]
    assert acc.mismatches(EXACT) == {}, (acc.injected, acc.expected, acc.observed)
    # late frames and unexpected ACKs depend on what came next and when: bounds, explained in
    # eyeq_spi.faults.soak's docstring
    assert acc.out_of_bounds() == {}, (acc.injected, acc.bounds, acc.observed)
    assert acc.observed["lateFrames"] == acc.observed["sequenceErrorCounter"]  # L6a, no resync


def test_vision_is_reached_and_held_at_5_percent_frame_loss() -> None:
    r = run_soak(SoakConfig(profile=FaultProfile.with_loss(0.05), duration=4.0, seed=1,
                            faults_from_start=True))
    assert r.reached_vision_at is not None and r.held, r.host
    assert r.corrupted == 0
    if not (r.host["eyeq_resets"] or r.host["boot_failures"]):  # then every fault is accounted
        assert all(a.ok for a in r.accounting.values()), r.accounting


def test_vision_is_reached_at_10_percent_frame_loss() -> None:
    r = run_soak(SoakConfig(profile=FaultProfile.with_loss(0.10), duration=0.5, seed=2,
                            faults_from_start=True))
    assert r.reached_vision_at is not None, r.host
    assert r.corrupted == 0


def _frames(n: int) -> list[bytes]:
    codec = FrameCodec()
    return [codec.data_frame(0, i % 4096, bytes([i & 0xFF]) * 50) if i % 2 else codec.ack(i % 4096)
            for i in range(n)]


def test_channel_is_seeded_and_its_rates_match_the_profile() -> None:
    frames = _frames(20_000)
    a, b = FaultyChannel(FaultProfile(), 7), FaultyChannel(FaultProfile(), 7)
    assert [a(f) for f in frames[:3000]] == [b(f) for f in frames[:3000]]
    ch = FaultyChannel(FaultProfile(), 3)
    for f in frames:
        ch(f)
    n = len(frames)
    for kind in ("drop", "duplicate", "reorder", "truncate"):
        got = ch.stats.injected[kind]
        assert abs(got - 0.01 * n) < 5 * math.sqrt(0.01 * n), (kind, got)
    flips = sum(len(r.bits) for r in ch.injected if r.kind == "flip")
    expected = 1e-5 * ch.stats.bits
    assert abs(flips - expected) < 5 * math.sqrt(expected), (flips, expected)
    # the pad of an ACK is outside its CRC (L3): such a flip is recorded as not covered
    assert all(r.crc_covered == (r.frame == "DATA" or min(r.bits) < 48)
               for r in ch.injected if r.kind == "flip")


def test_loss_profile_and_bad_profiles() -> None:
    assert abs(FaultProfile.with_loss(0.05).expected_frame_loss - 0.05) < 0.002
    with pytest.raises(UsageError, match="sum to less than 1"):
        FaultProfile(drop=0.5, duplicate=0.5)
    with pytest.raises(UsageError, match="below the profile's own"):
        FaultProfile.with_loss(0.01)
    with pytest.raises(UsageError, match="ber must be in"):
        FaultProfile(ber=1.0)
