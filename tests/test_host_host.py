"""A host with nobody listening skips the DASP field values but reports exactly what
a host with a subscriber reports: counters, E2E errors, DASP counter gaps, stale streams."""

from __future__ import annotations

from typing import Any

from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import DecodedMessage, MessageCodec
from eyeq_spi.conformance.mutants import DaspCounterStuck, E2eWrong
from eyeq_spi.host.host import HostEmulator
from eyeq_spi.host.machine import HostState
from eyeq_spi.phy.memory import memory_pair
from eyeq_spi.runner.virtual import VirtualRunner
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.sim.eyeq import SimulatedEyeQ


class _Both(E2eWrong, DaspCounterStuck):
    """EYEQ_VIS_AEB_INFO_MSG with a wrong E2E CRC and 0xA0 with a stuck counter."""

    def rewrite(self, message: bytes) -> bytes:
        return E2eWrong.rewrite(self, DaspCounterStuck.rewrite(self, message))


def _report(listen: bool, sim_cls: type[SimulatedEyeQ]) -> tuple[dict[str, Any], list[Any]]:
    sim = sim_cls(SimConfig(stop_dasp={"EYEQ_VIS_SRP_MSG": 2.0}))
    host = HostEmulator(reset_line=sim.power_up, keep_rx_times=True)
    got: list[DecodedMessage] = []
    if listen:
        host.subscribe(got.append)
    a, b = memory_pair()
    runner = VirtualRunner([(host, a), (sim, b)])
    sim.power_up(0.0)
    host.start(0.0)
    runner.run_until(3.0)
    assert host.state is HostState.RUNNING_VISION
    c = host.counters
    return {
        "received": dict(c.received), "rx_times": c.rx_times, "gaps": c.dasp_counter_gaps,
        "e2e": c.e2e_errors, "decode": c.decode_errors, "stale": sorted(host.stale_streams),
        "stale_events": dict(c.stale_events), "transitions": host.transitions,
    }, got


def test_nobody_listening_reports_the_same() -> None:
    quiet, none = _report(False, _Both)
    heard, got = _report(True, _Both)
    assert none == []
    assert quiet == heard
    assert quiet["e2e"] > 0 and quiet["gaps"] > 0  # the faults were there to be counted
    assert "EYEQ_VIS_SRP_MSG" in quiet["stale"]
    # and a subscriber still gets every field, as the codec decodes them
    obstacles = [m for m in got if m.name == "EYEQ_VIS_OBSTACLES_MSG"]
    assert obstacles and all(m.fields for m in got)
    assert obstacles[0].fields["visObjects"]["visObs"][0].keys() >= {"id", "physicalState"}


def test_fields_false_gives_the_same_errors_without_values() -> None:
    codec = MessageCodec()
    msg = codec.message("EYEQ_VIS_AEB_INFO_MSG")
    wire = bytearray(codec.encode_dasp(msg.name, codec.layout(msg).zero_values(), 7, E2EState()))
    for data in (bytes(wire), bytes(wire[:-1]), bytes(wire[:4]) + bytes(len(wire) - 4)):
        full = codec.decode(data, E2EState())
        lean = codec.decode(data, E2EState(), fields=False)
        assert (lean.name, lean.header, lean.errors) == (full.name, full.header, full.errors)
        assert lean.fields == {}
    assert codec.decode(bytes(wire[:4]) + bytes(len(wire) - 4), E2EState()).errors  # a bad CRC
