"""Express instants (runner/express.py) give the same transfers at the same virtual times, and
leave host, simulated EyeQ and link in the same state, as the general per-frame loop (the
reference, ``express=False`` or ``EYEQ_SPI_EXACT=1``): on clean runs and on the faults and
resets the emulator can inject."""

from __future__ import annotations

import random
from typing import Any

import pytest

from eyeq_spi.emulator import HOST_ALONE, Emulation, build
from eyeq_spi.host.machine import HostState
from eyeq_spi.phy.memory import MemoryAdapter
from eyeq_spi.runner.express import EXACT_ENV, Express
from eyeq_spi.runner.virtual import VirtualRunner
from eyeq_spi.sim.config import SimConfig

Trace = list[tuple[int, float, bytes]]


def _emulation(express: bool, cfg: SimConfig) -> tuple[Emulation, Trace]:
    trace: Trace = []
    emu = build(sim_config=cfg, keep_rx_times=False)
    emu.runner = VirtualRunner(emu.runner.nodes, tap=lambda i, t, b: trace.append((i, t, b)),
                               self_contained=HOST_ALONE, express=express)
    return emu, trace


def _state(emu: Emulation) -> dict[str, Any]:
    """What both paths must agree on besides the wire: counters of every layer, the host's
    state machine history, the adapters' statistics, the clock."""
    host, sim = emu.host, emu.sim
    return {
        "now": emu.runner.now,
        "host_state": host.state,
        "transitions": list(host.transitions),
        "host_counters": repr(host.counters),
        "sim_counters": repr(sim.counters),
        "links": [repr(n.conn.link.counters) for n in (host, sim)],
        "ack_latency": [dict(n.conn.link.ack_latency) for n in (host, sim)],
        "transport": [repr(n.conn.counters) for n in (host, sim)],
        "adapters": [repr(a.stats) for _, a in emu.runner.nodes],
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


@pytest.mark.parametrize("case", list(CASES))
def test_express_gives_the_reference_transfers_and_state(case: str) -> None:
    cfg, seconds = CASES[case]
    runs = []
    for express in (False, True):
        emu, trace = _emulation(express, SimConfig(**vars(cfg)))
        emu.run_for(seconds)
        runs.append((emu, trace))
    (ref, ref_trace), (fast, fast_trace) = runs
    assert len(ref_trace) > 1000
    assert _first_difference(ref_trace, fast_trace) is None, \
        _first_difference(ref_trace, fast_trace)
    assert _state(ref) == _state(fast)
    loop = fast.runner._express
    assert ref.runner._express is None
    assert loop is not None and loop.instants > 0.8 * len({t for _, t, _ in fast_trace})


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
