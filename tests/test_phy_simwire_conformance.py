"""The conformance suite on SPI adapters over the **simulated wire** (tests/simwire), not
hardware: ``conformance --dut eyeq`` against ``eyeq-spi sim`` and ``--dut host`` against
``eyeq-spi host``, each process on its own pair of simulated spidev channels.

Bounded wall-clock tests (``realtime``). The schedule on the simulated wire is that of Python
threads on a possibly loaded machine, not a rig's, so the cases that turn on it (rates, ACK
times, gaps) are left to the suite's report; every other case must pass.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.conformance.cases import cases_for
from eyeq_spi.conformance.model import TIMING
from tests.test_phy_simwire import EYEQ_SPIDEV, HOST_SIDE, LIGHT, Wire, finish

pytestmark = pytest.mark.realtime
SPIDEV_PAIR = {"spidev0.0": "spidev1.0", "spidev1.1": "spidev0.1"}
# cases that need a schedule the DUT may or may not produce in a given run
SCHEDULE = {"HOST-STALE", "LINK-WINDOW", "LINK-TXTIMEOUT", "LINK-GAP"}
# where a DATA frame lost to a late ACK shows besides the timing cases
SHOWS_LOSS = {"DASP-COUNTER", "DASP-E2E", "LINK-NUM"}
# both suites in CI only; a local run (the README's test command, 6 minutes at most) takes
# both suites over TCP (tests/test_cli_conformance.py) and the adapters' own tests
IN_CI = bool(os.environ.get("CI"))


def _verdicts(stdout: str) -> dict[str, dict[str, Any]]:
    return {r["id"]: r for r in map(json.loads, stdout.splitlines()) if r["kind"] == "case"}


def _judge(dut: str, stdout: str, stderr: str, not_run: set[str]) -> None:
    """Every case judged; every case that does not turn on the schedule passes (or, for the
    sessions an SPI rig cannot start, skips saying so). A frame lost to a late ACK shows in
    the sequence and counter cases too: they may fail only in a run whose timing cases show
    the schedule broke down."""
    recs = _verdicts(stdout)
    cases = {c.id: c for c in cases_for(dut)}
    assert set(cases) <= set(recs), (set(cases) - set(recs), stderr[-2000:])
    late = [k for k, c in cases.items() if c.rule == TIMING and recs[k]["verdict"] == "fail"]
    for case_id, case in cases.items():
        verdict, evidence = recs[case_id]["verdict"], recs[case_id]["evidence"]
        if case.rule == TIMING or case_id in SCHEDULE:
            continue  # the simulation's schedule, not a rig's; the suite reports it
        if case_id in not_run:
            assert verdict == "skip" and "did not run" in evidence, (case_id, evidence)
        elif late and case_id in SHOWS_LOSS:
            assert verdict in ("pass", "fail"), (case_id, verdict, evidence)
        else:
            assert verdict == "pass", (case_id, verdict, evidence, late)


@pytest.mark.skipif(not IN_CI, reason="CI only (about 15 s): the README's local test run "
                    "takes the host suite over the simulated wire")
def test_the_eyeq_suite_against_a_simulated_eyeq_on_simulated_adapters(tmp_path: Path) -> None:
    wire = Wire(tmp_path, links=SPIDEV_PAIR,
                latency_us=0, jitter_us=0)
    conf = wire.start("conformance", "--dut", "eyeq", "--port", HOST_SIDE, "--json")
    wire.wait_open("spidev0.1")
    sim = wire.start("sim", "--listen", EYEQ_SPIDEV, "--duration", "90", *LIGHT)
    try:
        _, out, err = finish(conf, 120)
    finally:
        sim.kill()
        sim.communicate()
    _judge("eyeq", out, err, set())


@pytest.mark.skipif(not IN_CI, reason="CI only (about 12 s): the README's local test run "
                    "takes the host suite over TCP and the SPI adapters' own tests")
def test_the_host_suite_against_the_host_emulator_on_simulated_adapters(tmp_path: Path) -> None:
    wire = Wire(tmp_path, links=SPIDEV_PAIR,
                latency_us=0, jitter_us=0)
    host = wire.start("host", "--port", HOST_SIDE, "--duration", "90", "--reconnect",
                      "--nvm", str(tmp_path / "nvm.json"))
    wire.wait_open("spidev0.1")
    conf = wire.start("conformance", "--dut", "host", "--listen", EYEQ_SPIDEV, "--json",
                      "--accept-timeout", "30")
    try:
        _, out, err = finish(conf, 120)
    finally:
        host.kill()
        host.communicate()
    # SPI lines have no hang-up: the suite ends each ignition cycle by falling silent
    # (SpiAdapter.drop), the host takes the link as lost and starts its next cycle
    _judge("host", out, err, set())
