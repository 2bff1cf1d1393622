"""The conformance suite in real time against ``eyeq-spi sim`` and ``eyeq-spi host`` run as
separate processes, over TCP and over a pty. Bounded wall-clock tests.

Both DUT kinds run the whole suite: the EyeQ one session, the host its three ignition cycles
(over TCP the host reconnects; over --pty each cycle gets a fresh pty and a new host process
opens it). Our own implementations are conformant, so no case may fail. On a loaded machine
the timing cases may come out ``inconclusive``, but only with the evidence of our own loop's
stalls in the same run (conformance/load.py); every case that does not turn on the schedule
must pass.

Over a pty the kernel hands each write to the reader from a worker thread at ordinary priority
(tests/test_soak_live.py), which other work on the machine can delay by several milliseconds
whatever the priority of the two processes; neither side's loop sees it. So over a pty a timing
case may also fail, but only with the suite's own words that our side did not cause it; its
content cases must pass as over TCP."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.conformance.cases import cases_for
from eyeq_spi.conformance.load import NOT_OURS
from eyeq_spi.conformance.model import TIMING
from tests.sim_proc import start_sim

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "eyeq_spi.cli"]
LIGHT = ["--objects", "1", "--signs", "1", "--light-spots", "1"]
# not observable on the link (a host reports stale streams elsewhere)
UNOBSERVABLE = {"HOST-STALE"}
# rules our implementations may not exercise in a given run: a skip that says why, never a pass
# (our host sends single frames only; W = 8 unacknowledged frames within ackTimeout depends on
# how many frames the DUT had queued during the ACK blackout)
MAY_SKIP = {"LINK-WINDOW", "LINK-TXTIMEOUT", "LINK-GAP"}
# both transports in CI; a local run (the README's test command) takes TCP only: the pty adds
# no rule of the suite, only the pty adapter, which tests/test_phy.py's contract covers
TRANSPORTS = ["tcp", "pty"] if os.environ.get("CI") else ["tcp"]


def _records(stdout: str) -> dict[str, dict[str, Any]]:
    out = {}
    for line in stdout.splitlines():
        rec = json.loads(line)
        out[rec["id"] if rec["kind"] == "case" else rec["kind"]] = rec
    return out


def _judge_run(dut: str, code: int, stdout: str, stderr: str, where: str = "tcp") -> None:
    recs = _records(stdout)
    ids = {c.id for c in cases_for(dut)}
    assert ids <= set(recs), (ids - set(recs), stderr[-2000:])
    assert recs["header"]["dut"] == dut and recs["header"]["time"] == "real"
    failed = {k: r for k, r in recs.items() if r.get("verdict") == "fail"}
    # over a pty: a timing fail the suite did not lay at our side's door (docstring above)
    excused = {k for k, r in failed.items()
               if where == "pty" and r["rule"] == TIMING and NOT_OURS in r["evidence"]}
    if code != 0 and set(failed) != excused:  # every word: a rare failure must be readable
        said = "\n".join(f"{k}: {r['evidence']}" for k, r in failed.items())
        pytest.fail(f"exit {code}\n{said}\n--- stderr\n{stderr[-2000:]}", pytrace=False)
    for k in ids:
        rec = recs[k]
        v, ev = rec["verdict"], rec["evidence"]
        assert ev, k
        if k in UNOBSERVABLE:
            assert v == "inconclusive", (k, ev)
        elif v == "skip" and k in MAY_SKIP:
            assert "the DUT" in ev, (k, ev)
        elif next(c for c in cases_for(dut) if c.id == k).rule == TIMING:
            # a timing case: pass, or inconclusive because our own loop stalled
            assert v == "pass" or (v == "inconclusive" and "our own loop stalled" in ev) \
                or k in excused, (k, v, ev)
            assert "our own loop" in ev  # the gauge is stated either way
        else:
            assert v == "pass", (k, v, ev)


@pytest.mark.realtime
@pytest.mark.parametrize("where", TRANSPORTS)
def test_eyeq_suite_against_a_sim_process(where: str) -> None:
    how = ["--listen", "tcp://127.0.0.1:0"] if where == "tcp" else ["--pty"]
    sim, url = start_sim(*how, "--duration", "90", "--accept-timeout", "30", *LIGHT)
    try:
        res = subprocess.run([*CLI, "conformance", "--dut", "eyeq", "--port", url,
                              "--json"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    finally:
        sim.kill()
        sim.wait(timeout=10)
    _judge_run("eyeq", res.returncode, res.stdout, res.stderr, where)


def _stop(conf: subprocess.Popen[str], host: subprocess.Popen[bytes] | None,
          reader: threading.Thread) -> None:
    """The suite's and the host's processes gone, the suite's stderr read to its end."""
    conf.kill()
    conf.wait(timeout=10)
    if host is not None:
        host.kill()
        host.wait(timeout=10)
    reader.join(timeout=5)


@pytest.mark.realtime
@pytest.mark.parametrize("where", TRANSPORTS)
def test_host_suite_against_host_processes(where: str, tmp_path: Path) -> None:
    how = ["--listen", "tcp://127.0.0.1:0"] if where == "tcp" else ["--pty"]
    conf = subprocess.Popen([*CLI, "conformance", "--dut", "host", *how, "--json",
                             "--accept-timeout", "30"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    urls: list[str] = []
    err: list[str] = []

    def read_stderr() -> None:  # LISTEN URL once, or PTY PATH once per ignition cycle
        assert conf.stderr is not None
        for raw in conf.stderr:
            err.append(raw)
            part = raw.split()
            if len(part) == 2 and part[0] in ("LISTEN", "PTY"):
                urls.append(part[1])

    reader = threading.Thread(target=read_stderr, daemon=True)
    reader.start()
    host: subprocess.Popen[bytes] | None = None
    used = None
    out = ""
    try:
        deadline = time.monotonic() + 150
        while conf.poll() is None and time.monotonic() < deadline:
            # one ECU: its NVM outlives the ignition cycle; a new cycle is a new connection
            if urls and (host is None or host.poll() is not None or used != len(urls)):
                if host is not None:
                    host.kill()
                    host.wait(timeout=10)
                used = len(urls)
                # over TCP the host reconnects by itself; a pty path may be reused by the
                # next cycle's pty, so there each cycle gets a new host process and no other
                again = ["--reconnect"] if where == "tcp" else []
                host = subprocess.Popen(
                    [*CLI, "host", "--port", urls[-1], "--duration", "60", *again,
                     "--nvm", str(tmp_path / "nvm.json")],
                    cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            time.sleep(0.05)
        assert conf.poll() is not None, "the suite did not finish within 150 s"
        assert conf.stdout is not None
        out = conf.stdout.read()
    finally:
        _stop(conf, host, reader)
    if where == "pty":
        assert len(urls) == 3  # one pty per ignition cycle
    _judge_run("host", conf.returncode, out, "".join(err), where)


@pytest.mark.realtime
def test_a_real_violation_still_fails_in_real_time() -> None:
    """A sim process whose MESP replies leave 700 ms late (its --reply-delay fault switch):
    MESP-DEADLINE fails, and the gauge says our own loop was not the cause (a stall of 100 ms
    would be needed to excuse 200 ms of lateness)."""
    sim, url = start_sim("--listen", "tcp://127.0.0.1:0", "--duration", "60",
                         "--accept-timeout", "30", "--reply-delay", "0.7", *LIGHT)
    try:
        res = subprocess.run([*CLI, "conformance", "--dut", "eyeq", "--port", url, "--json",
                              "-k", "MESP-DEADLINE or LINK-SIZE"], cwd=ROOT,
                             capture_output=True, text=True, timeout=120)
    finally:
        sim.kill()
        sim.wait(timeout=10)
    recs = _records(res.stdout)
    assert res.returncode in (0, 1), res.stderr[-2000:]
    assert recs["LINK-SIZE"]["verdict"] == "pass"
    deadline = recs["MESP-DEADLINE"]
    if "the machine was loaded" in deadline["evidence"]:  # a stall of >= 100 ms: excused
        assert deadline["verdict"] == "inconclusive", deadline
    else:
        assert deadline["verdict"] == "fail" and res.returncode == 1, deadline
        assert "> 500 ms" in deadline["evidence"]
        assert "not caused by our side" in deadline["evidence"]


@pytest.mark.realtime
def test_one_reconnecting_host_gets_through_every_ignition_cycle(tmp_path: Path) -> None:
    """docs/conformance.md's two commands: the suite listening (its stderr a pipe, not a
    terminal) and ONE ``eyeq-spi host --reconnect`` process, never restarted. The host stops
    after the bad EEPROM (HOST-EEPROM-BAD watches it, connected and quiet, for at least 1 s)
    and still joins the next ignition cycle; every session announces on stderr that it waits
    for the host."""
    conf = subprocess.Popen([*CLI, "conformance", "--dut", "host", "--listen",
                             "tcp://127.0.0.1:0", "--json", "--accept-timeout", "30", "-k",
                             "HOST-VERSIONS or HOST-EEPROM-BAD or HOST-BOOT-RESETS"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    urls: list[str] = []
    err: list[str] = []
    listening = threading.Event()

    def read_stderr() -> None:
        assert conf.stderr is not None
        for raw in conf.stderr:
            err.append(raw)
            part = raw.split()
            if len(part) == 2 and part[0] == "LISTEN":
                urls.append(part[1])
                listening.set()

    reader = threading.Thread(target=read_stderr, daemon=True)
    reader.start()
    host: subprocess.Popen[bytes] | None = None
    out = ""
    try:
        assert listening.wait(60), f"the suite did not listen: {''.join(err)[-500:]}"
        host = subprocess.Popen(
            [*CLI, "host", "--port", urls[0], "--reconnect", "--duration", "300",
             "--nvm", str(tmp_path / "nvm.json")],
            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:  # its --json output is a few lines: the pipe cannot fill up meanwhile
            conf.wait(timeout=150)
        except subprocess.TimeoutExpired:
            raise AssertionError("the suite did not finish within 150 s") from None
        assert host.poll() is None, "the host under test exited before the suite ended"
        assert conf.stdout is not None
        out = conf.stdout.read()
    finally:
        _stop(conf, host, reader)
    recs = _records(out)
    stderr = "".join(err)
    assert conf.returncode == 0, (recs, stderr[-2000:])
    for session in ("normal", "eeprom_bad", "boot_fail"):
        assert f"session {session}: waiting up to 30 s for the host to connect to {urls[0]}" \
            in stderr, stderr
    for k in ("HOST-VERSIONS", "HOST-EEPROM-BAD", "HOST-BOOT-RESETS"):
        assert recs[k]["verdict"] == "pass", (k, recs[k]["evidence"])
    assert "at least 1.0 s" in recs["HOST-EEPROM-BAD"]["evidence"]
