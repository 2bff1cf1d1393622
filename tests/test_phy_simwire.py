"""The three jobs and ``bench doctor`` on SPI adapters over a **simulated wire**, not hardware.

Each command runs as its own process with ``tests/simwire`` first on ``PYTHONPATH``, so the
product imports the simulated ``spidev`` and ``ft4222`` modules there instead of the real
packages (the product is not patched and does not know). The simulated wire carries each
transfer between processes as one UDP datagram on the loopback interface, with a modelled USB
latency and jitter, chip-select framing and injected faults (tests/simwire/simwire.py).
What it cannot show: a real controller's timing, a real FT4222H or spi-slave driver, real
signal integrity; the ``hardware`` tests (tests/test_phy_hardware.py) are for that.

Bounded wall-clock tests (``realtime``). The timing on the simulated wire is that of Python
threads on a possibly loaded machine, not a rig's: the job tests judge the bring-up, the rates
(no stream goes stale) and the integrity of what was received. The conformance suite over the
simulated wire: tests/test_phy_simwire_conformance.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.catalog.messages import catalog
from tests.waiting import wait_until

ROOT = Path(__file__).resolve().parents[1]
SIMWIRE = ROOT / "tests" / "simwire"
CLI = [sys.executable, "-m", "eyeq_spi.cli"]
LIGHT = ["--objects", "1", "--signs", "1", "--light-spots", "1"]
# the host emulator's SPI side (spidev) and the simulated EyeQ's (two FT4222H), wired to
# each other: each master to the other side's slave
HOST_SIDE = "spidev:///dev/spidev0.0,spidev:///dev/spidev0.1"
EYEQ_SIDE = "ft4222://0,ft4222://1"
EYEQ_SPIDEV = "spidev:///dev/spidev1.1,spidev:///dev/spidev1.0"

# a long run in CI (the 30 s), a short one locally (the README's test command)
DEMO_S = 30 if os.environ.get("CI") else 5

pytestmark = pytest.mark.realtime
# the EyeQ's vision streams and their rates, Hz (seed 004's message table)
RATES = {m.name: m.rate_hz for m in catalog().messages
         if m.rate_hz and m.name.startswith("EYEQ_VIS_")}


class Wire:
    """One simulated wire: its directory, its settings, and commands run on it."""

    def __init__(self, path: Path, **settings: Any) -> None:
        self.path = path
        conf = {"links": {"spidev0.0": "ES", "EM": "spidev0.1"}, "ft4222": ["EM", "ES"],
                "latency_us": 50, "jitter_us": 50}
        conf.update(settings)
        (path / "wire.json").write_text(json.dumps(conf))
        self.env = dict(os.environ, EYEQ_SPI_SIMWIRE=str(path),
                        PYTHONPATH=os.pathsep.join([str(SIMWIRE), str(ROOT)]))

    def run(self, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
        return subprocess.run([*CLI, *args], cwd=ROOT, env=self.env, capture_output=True,
                              text=True, timeout=timeout)

    def start(self, *args: str) -> subprocess.Popen[str]:
        return subprocess.Popen([*CLI, *args], cwd=ROOT, env=self.env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)

    def wait_open(self, device: str, timeout: float = 60) -> None:
        """Until ``device`` is open (a slow machine takes a while to import and warm up)."""
        wait_until((self.path / f"{device}.conf").exists, timeout, f"{device} opened")

    def wait_sent(self, device: str, transfers: int, timeout: float = 60) -> None:
        """Until the master ``device`` has sent ``transfers`` transfers (its count is published
        every 100): progress on the wire, which a loaded machine slows as much as the run."""
        sent = self.path / f"{device}.sent"
        wait_until(lambda: sent.exists() and int(sent.read_text() or 0) >= transfers, timeout,
                   f"{device} sent {transfers} transfers")

    def unplug(self, device: str) -> None:
        (self.path / f"{device}.unplugged").touch()


def finish(proc: subprocess.Popen[str], timeout: float) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"did not end within {timeout} s: {err[-2000:]}")
    return proc.returncode, out, err


# -- bench doctor ----------------------------------------------------------------------------
def test_the_doctor_finds_a_loop_of_simulated_spidev_fit(tmp_path: Path) -> None:
    wire = Wire(tmp_path, links={"spidev0.0": "spidev0.1"}, latency_us=100, jitter_us=100)
    res = wire.run("bench", "doctor", "spidev:///dev/spidev0.0,spidev:///dev/spidev0.1")
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.startswith("bench doctor: FIT for a live EyeQ: 400 transfers intact")


def test_the_doctor_says_no_to_a_rig_slower_than_the_ack_timeout(tmp_path: Path) -> None:
    wire = Wire(tmp_path, links={"HM": "ES", "EM": "HS"}, ft4222=["HM", "HS", "EM", "ES"],
                latency_us=12_000, jitter_us=500)
    res = wire.run("bench", "doctor", "ft4222://0,ft4222://1", "--peer",
                   "ft4222://2,ft4222://3", "--frames", "10", "--json")
    assert res.returncode == 1, res.stdout + res.stderr
    report = json.loads(res.stdout)
    assert not report["fit"] and report["outcomes"] == {"intact": 40}
    assert report["round_trip_ms"]["p50"] > 10.0
    assert any("not under the 10 ms ackTimeout" in r for r in report["reasons"])


def test_the_doctor_says_no_when_the_two_ends_disagree_on_the_spi_mode(tmp_path: Path) -> None:
    wire = Wire(tmp_path, links={"HM": "ES", "EM": "HS"}, ft4222=["HM", "HS", "EM", "ES"])
    bench = tmp_path / "peer.toml"
    bench.write_text('[master]\nurl = "ft4222://2"\n[slave]\nurl = "ft4222://3"\n'
                     "[spi]\nmode = 0\n")
    res = wire.run("bench", "doctor", "ft4222://0,ft4222://1", "--peer", str(bench),
                   "--frames", "5")
    assert res.returncode == 1, res.stdout + res.stderr
    assert "NOT FIT" in res.stdout and "disagree on the SPI mode" in res.stdout


def test_the_doctor_names_transfers_cut_short(tmp_path: Path) -> None:
    # every 5th transfer: chip select rises early; every 7th: the slave loses bytes (overrun)
    wire = Wire(tmp_path, links={"spidev0.0": "spidev0.1"}, cs_short_every=5,
                overrun_every=7)
    res = wire.run("bench", "doctor", "spidev:///dev/spidev0.0,spidev:///dev/spidev0.1",
                   "--frames", "35", "--json")
    assert res.returncode == 1, res.stdout + res.stderr
    report = json.loads(res.stdout)
    assert report["outcomes"]["short"] == 70 // 5 + 70 // 7 - 70 // 35
    assert any("short (chip select rose early)" in r for r in report["reasons"])


# -- the three jobs --------------------------------------------------------------------------
def test_host_and_simulated_eyeq_on_their_own_simulated_adapters_reach_running_vision(
        tmp_path: Path) -> None:
    # a short modelled USB round trip: the doctor's tests take the slow ones
    wire = Wire(tmp_path, latency_us=0, jitter_us=50)
    host = wire.start("host", "--port", HOST_SIDE, "--duration", str(DEMO_S), "--json")
    wire.wait_open("spidev0.1")
    # the simulated EyeQ outlives the host by a little: the host holds Running Vision to its
    # end, and the EyeQ ends its session when the host falls silent
    sim = wire.start("sim", "--listen", EYEQ_SIDE, "--duration", str(DEMO_S + 3), "--json",
                     *LIGHT)
    _, out, err = finish(host, DEMO_S + 60)
    s = json.loads(out)
    _, sim_out, _ = finish(sim, 60)  # it sees the host fall silent and ends its session
    assert s["running_vision_since"] is not None, (s["problem"], err[-2000:])
    assert s["transitions"][-1]["to"] == "RUNNING_VISION"  # reached and held to the end
    assert s["link_lost"] is None, s["problem"]
    # the rates held: every stream of the vision app arrived at 80 % of its rate or more from
    # Running Vision to the end (a frame that misses ackTimeout on a loaded machine costs its
    # message, counted in the summary, and the test prints the summary's problem)
    running = s["elapsed_s"] - s["running_vision_since"]
    for name, rate in RATES.items():
        got = s["received"].get(name, 0)
        assert got >= 0.8 * rate * running, (name, got, rate, running, s["problem"])
    assert s["link"]["dataCRCErrorCounter"] == s["link"]["formatErrorCounter"] == 0
    assert s["decode_errors"] == 0
    assert s["spi"]["adapter"] == HOST_SIDE and s["spi"]["reply_latency_ms"]["n"] > 100
    served = json.loads(sim_out)["sessions"]
    assert len(served) == 1 and "nothing from the peer" in served[0]["link_lost"]
    assert served[0]["running_vision_since"] is not None


def test_short_transfers_are_counted_and_an_unplug_ends_the_run_with_link_lost(
        tmp_path: Path) -> None:
    # every 40th transfer on the wire: chip select rises after 60 bytes
    wire = Wire(tmp_path, cs_short_every=40, cs_short_len=60)
    host = wire.start("host", "--port", HOST_SIDE, "--duration", "60", "--json")
    wire.wait_open("spidev0.1")
    sim = wire.start("sim", "--listen", EYEQ_SIDE, "--duration", "60", *LIGHT)
    try:
        # Running Vision comes after about 700 of the EyeQ's transfers (0.6 s on a quiet
        # machine); 3,000 leave it time to hold there however loaded the machine is
        wire.wait_sent("EM", 3000)
        wire.unplug("spidev0.0")  # the host's master channel: its USB adapter pulled out
        code, out, err = finish(host, 30)
    finally:
        sim.kill()
        sim.communicate()
    assert code == 1, out + err[-2000:]
    s = json.loads(out)
    assert not s["ok"] and "link lost" in s["link_lost"] and "spidev0.0" in s["link_lost"]
    assert s["link"]["formatErrorCounter"] > 0  # the short transfers, counted (L8)
    assert s["link"]["dataCRCErrorCounter"] == 0 and s["decode_errors"] == 0  # nothing bad
    assert s["running_vision_since"] is not None
