"""Output hygiene of the CLI, in a pseudo-terminal where it matters: the progress bar goes to
stderr on a TTY only, a closed pipe ends quietly, --json is pure JSON Lines, --stats honours the
filters, wireshark writes to stdout, and the live view of demo fits 100 columns on one time
base and explains the first-run FATAL_22."""

from __future__ import annotations

import io
import json
import os
import pty
import select
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.cli import main

CLI = [sys.executable, "-m", "eyeq_spi.cli"]


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One second of demo traffic (virtual time): DASP, MESP, DIAG and BOOT messages."""
    path = tmp_path_factory.mktemp("cap") / "demo.pcapng"
    with open(os.devnull, "w") as null:
        r = subprocess.run([*CLI, "demo", "--virtual-time", "--duration", "1.5", "--capture",
                            str(path)], stdout=null, stderr=subprocess.PIPE, timeout=120)
    assert r.returncode == 0, r.stderr
    return path


def _run_in_pty(argv: list[str], *, stdout_tty: bool = False,
                timeout: float = 60) -> tuple[int, bytes, bytes]:
    """Run with stderr (and optionally stdout) on a pty; return (rc, stdout, pty bytes)."""
    master, slave = pty.openpty()
    out_pipe = slave if stdout_tty else subprocess.PIPE
    env = {**os.environ, "COLUMNS": "100", "TERM": "xterm"}
    p = subprocess.Popen([*CLI, *argv], stdin=subprocess.DEVNULL, stdout=out_pipe, stderr=slave,
                         env=env)
    os.close(slave)
    tty = b""
    out = b""
    streams = [master] + ([p.stdout.fileno()] if p.stdout else [])
    while streams:
        ready, _, _ = select.select(streams, [], [], timeout)
        if not ready:
            p.kill()
            pytest.fail(f"{argv} hung")
        for fd in ready:
            try:
                data = os.read(fd, 65536)
            except OSError:  # the pty closes with EIO when the child is gone
                data = b""
            if not data:
                streams.remove(fd)
            elif fd == master:
                tty += data
            else:
                out += data
    os.close(master)
    return p.wait(timeout), out, tty


def test_progress_bar_goes_to_stderr_on_a_tty_and_never_into_stdout(capture: Path) -> None:
    """Records on a pipe (which may end on the same terminal, as ``| head`` does): no bar.
    ``--stats`` writes nothing until the end: the bar is drawn on the terminal."""
    rc, out, tty = _run_in_pty(["dissect", str(capture), "--json"])
    assert rc in (0, 1)
    assert b"\x1b" not in out  # no escape sequence, no bar in the records
    for line in out.decode().splitlines():
        json.loads(line)
    assert b"\x1b[?25l" not in tty and b"ETA" not in tty
    rc, out, tty = _run_in_pty(["dissect", str(capture), "--stats", "--json"])
    assert rc in (0, 1) and b"\x1b" not in out
    json.loads(out)
    assert b"\x1b[?25l" in tty  # rich drew (and hid the cursor for) the bar on the terminal


def test_no_progress_bar_without_a_tty(capture: Path) -> None:
    r = subprocess.run([*CLI, "dissect", str(capture), "--stats"], capture_output=True,
                       timeout=60)
    assert r.returncode in (0, 1) and r.stderr == b"" and b"\x1b" not in r.stdout


def test_no_progress_bar_while_records_scroll_on_the_same_terminal(capture: Path) -> None:
    rc, _, tty = _run_in_pty(["dissect", str(capture), "--no-tree"], stdout_tty=True)
    assert rc in (0, 1) and b"\x1b[?25l" not in tty and b"NUM=" in tty


def test_a_closed_pipe_ends_quietly(capture: Path) -> None:
    p = subprocess.Popen([*CLI, "dissect", str(capture), "--json"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    assert p.stdout is not None and p.stderr is not None
    first = p.stdout.readline()
    p.stdout.close()  # what `| head -1` does
    err = p.stderr.read()
    assert p.wait(60) == 0 and err == b"", err
    assert json.loads(first)["kind"] == "frame"


def _strict(line: str) -> Any:
    def no_constant(name: str) -> Any:
        raise ValueError(f"{name} is not JSON")

    return json.loads(line, parse_constant=no_constant)


def test_json_is_pure_json_lines(capture: Path, capsys: pytest.CaptureFixture[str]) -> None:
    main(["dissect", str(capture), "--json"])
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) > 1000
    kinds = {_strict(line)["kind"] for line in lines}
    assert kinds >= {"frame", "message"}


def test_json_writer_turns_non_finite_floats_into_null() -> None:
    from eyeq_spi.io.jsonl import JsonLinesWriter

    buf = io.StringIO()
    JsonLinesWriter(buf).write({"kind": "message", "fields": {"a": float("nan"), "b": [1.5, float(
        "inf")], "c": {"d": -float("inf")}}})
    assert _strict(buf.getvalue()) == {"kind": "message", "fields": {"a": None,
                                       "b": [1.5, None], "c": {"d": None}}}


def test_stats_honours_every_filter(capture: Path, capsys: pytest.CaptureFixture[str]) -> None:
    main(["dissect", str(capture), "--stats", "--json"])
    everything = _strict(capsys.readouterr().out)
    main(["dissect", str(capture), "--stats", "--json", "--protocol", "mesp"])
    mesp = _strict(capsys.readouterr().out)
    main(["dissect", str(capture), "--stats", "--json", "--id", "0xE4"])
    obstacles = _strict(capsys.readouterr().out)

    def names(stats: dict[str, Any]) -> set[str]:
        return {k for k, v in stats["messages"].items() if v}

    assert "EYEQ_VIS_OBSTACLES_MSG" in names(everything) and "GetEyeQVersions" in names(
        everything)
    from eyeq_spi.catalog.messages import catalog

    functions = {f.name for f in catalog().mesp} | {"MESP"}
    assert names(mesp) and names(mesp) <= functions, names(mesp)
    assert mesp["frames"] == {} or not any(mesp["frames"].values())  # frames were filtered
    assert names(obstacles) == {"EYEQ_VIS_OBSTACLES_MSG"}


def test_wireshark_writes_to_stdout_without_output(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["wireshark"]) == 0
    out = capsys.readouterr().out
    assert "Proto(" in out and "eyeq" in out.lower()


@pytest.mark.skipif(not os.path.exists("/dev/full") or not os.access("/dev/full", os.W_OK),
                    reason="needs a writable /dev/full (a full disk on every write)")
def test_wireshark_says_an_output_it_cannot_write_is_an_output_error(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["wireshark", "--output", "/dev/full"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("eyeq-spi: error: cannot write /dev/full"), err


@dataclass
class _State:
    value: str


@dataclass
class _T:
    time: float
    src: _State
    event: _State
    dst: _State
    detail: str = ""


class _Counters:
    def __init__(self) -> None:
        self.received: dict[str, int] = {}


class _Host:
    def __init__(self, t0: float) -> None:
        self.now = t0
        self.state = _State("WAIT_PENDING")
        self.transitions: list[_T] = []
        self.counters = _Counters()


def test_live_view_one_time_base_100_columns_and_fatal_22_explained() -> None:
    from eyeq_spi.cli.run import LiveView

    t0 = 84_000.0  # a host on the monotonic clock: transitions carry t0 + elapsed
    host = _Host(t0 + 0.2)
    buf = io.StringIO()
    view = LiveView(True, say=lambda line: print(line, file=buf))
    host.transitions.append(_T(t0 + 0.15, _State("POWER_UP"), _State("BOOT_OK"),
                               _State("WAIT_PENDING")))
    view.update(host, 0.2)
    host.transitions.append(_T(t0 + 0.3, _State("WAIT_RUNNING"), _State("FATAL_22"),
                               _State("READ_EEPROM"), "0x41 Fatal_Error 22 " + "x" * 80))
    host.transitions.append(_T(t0 + 0.9, _State("READ_EEPROM"), _State("FATAL_22"),
                               _State("READ_EEPROM")))
    host.counters.received = {f"EYEQ_STREAM_{i:02d}_WITH_A_LONG_NAME_MSG": 18 for i in range(20)}
    host.now = t0 + 1.2
    view.update(host, 1.2)
    lines = buf.getvalue().splitlines()
    assert all(len(line) <= 100 for line in lines), max(lines, key=len)
    stamps = [float(line[1:9]) for line in lines if line.startswith("[")]
    assert stamps == sorted(stamps) and stamps[0] == pytest.approx(0.15, abs=0.01)
    assert stamps[-1] == pytest.approx(1.2)
    notes = [line for line in lines if "empty" in line]
    assert len(notes) == 1 and "NVM" in notes[0]  # explained once, not per FATAL_22


def test_demo_live_view_in_a_pty() -> None:
    rc, out, tty = _run_in_pty(["demo", "--virtual-time", "--duration", "2"])
    text = tty.decode()
    assert rc == 0 and b"RUNNING_VISION" in out
    lines = [line for line in text.replace("\r", "").splitlines() if line]
    assert any("--FATAL_22-->" in line for line in lines) and "NVM is empty" in text
    assert any("msg/s" in line for line in lines)
    assert all(len(line) <= 100 for line in lines), max(lines, key=len)
