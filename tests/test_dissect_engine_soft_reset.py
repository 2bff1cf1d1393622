"""A host that starts its E2E rolling counters over after a soft reset (Switch EyeQ Application,
§7.1.1.7): the EyeQ application judges them afresh, and so do both dissector paths."""

from __future__ import annotations

from typing import Any

import pytest

from eyeq_spi.capture.pcapng_fast import chunks_from_transfers
from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect import engine
from eyeq_spi.dissect import engine_fast as batch
from tests.test_dissect_engine_fast import Wire

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

MC = MessageCodec()
VEH = "HOST_VEH_STATE_MSG"


def _capture(switch: bool, rounds: int = 40) -> list[Transfer]:
    """The host sends HOST_VEH_STATE_MSG, then (``switch``) Switch EyeQ Application to vision,
    then starts its E2E counters over; the EyeQ ACKs and answers."""
    wire = Wire()
    send = wire.send
    zero = MC.layout(MC.message(VEH)).zero_values()
    fs = "EYEQ_VIS_FAILSAFE_MSG"
    fs_zero, fs_e2e = MC.layout(MC.message(fs)).zero_values(), E2EState()
    counter = 0
    for k, e2e in enumerate((E2EState(), E2EState())):  # the second: counters start over
        for _ in range(rounds):
            send("h2e", MC.encode_dasp(VEH, zero, counter, e2e))
            send("e2h", MC.encode_dasp(fs, fs_zero, counter, fs_e2e))
            counter = (counter + 1) & 0xFF
            wire.t += 0.015
        if switch and k == 0:
            send("h2e", MC.mesp.encode_request("SwitchEyeQApplication", 7,
                                               {"applicationId": 1}))
            send("e2h", MC.mesp.encode_reply("SwitchEyeQApplication", 7, 0,
                                             {"applicationId": 1}))
    return [Transfer(t, d, w) for d, t, w in wire.out]


def _e2e_errors(recs: list[dict[str, Any]]) -> list[str]:
    return [e for r in recs if r.get("kind") == "message" and r["name"] == VEH
            for e in r["errors"]]


def test_without_a_switch_a_restart_of_the_counters_is_an_error() -> None:
    """The control: the same restart with no soft reset before it is reported."""
    errors = _e2e_errors(list(engine.iter_records(_capture(switch=False))))
    assert errors and all("counter" in e.lower() for e in errors)


def test_after_a_switch_the_counters_are_judged_afresh() -> None:
    recs = list(engine.iter_records(_capture(switch=True)))
    assert not _e2e_errors(recs)
    assert sum(r.get("name") == VEH for r in recs) == 80


@pytest.mark.parametrize("chunk", [7, 64, 1 << 15])
def test_batch_path_agrees(chunk: int) -> None:
    for switch in (False, True):
        recs = _capture(switch)
        want = list(engine.iter_records(recs))
        got = list(batch.iter_records(chunks_from_transfers(recs, chunk)))
        assert got == want
