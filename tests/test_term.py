"""The terminal side of the CLI: human dissect lines (time since the first record, direction),
the shared progress bar (stderr a terminal only, never between records on stdout), help,
version and shell completion."""

from __future__ import annotations

import json
import os
import re
import select
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.cli import main


@pytest.fixture(scope="module")
def demo_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """3 s of the emulator, bring-up included (about 1 MB of pcapng)."""
    path = tmp_path_factory.mktemp("term") / "demo.pcapng"
    assert main(["demo", "--virtual-time", "--duration", "3", "--capture", str(path),
                 "--json"]) == 0
    return path


def test_human_dissect_lines_carry_time_and_direction(
        demo_capture: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``dissect --id 0xE4``: every line says when (s since the capture's first record, the
    origin of plot's time axis, whatever the filter drops) and which direction."""
    assert main(["dissect", str(demo_capture), "--json"]) == 0
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    origin = records[0]["time"]
    want = [(round(r["time"] - origin, 6), r["direction"]) for r in records
            if r["kind"] == "message" and r["name"] == "EYEQ_VIS_OBSTACLES_MSG"]
    assert main(["dissect", str(demo_capture), "--id", "0xE4", "--no-tree"]) == 0
    lines = capsys.readouterr().out.splitlines()
    got = []
    for line in lines:
        m = re.fullmatch(r"\s+(\d+\.\d{6}) (e2h|h2e) DASP EYEQ_VIS_OBSTACLES_MSG .*", line)
        assert m, line
        got.append((float(m.group(1)), m.group(2)))
    assert got == want and got[0][0] > 0.3  # after the bring-up, not 0: the origin is the file's


def test_progress_only_where_it_cannot_garble_records(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from eyeq_spi import cli_progress as cp

    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    with open(tmp_path / "out", "w") as f, monkeypatch.context() as m:
        m.setattr(sys, "stdout", f)
        assert cp.bar_allowed(records_on_stdout=True)  # stdout a file
    r, w = os.pipe()
    with os.fdopen(w, "w") as f, monkeypatch.context() as m:
        m.setattr(sys, "stdout", f)
        assert not cp.bar_allowed(records_on_stdout=True)  # a pipe may end on this terminal
        assert cp.bar_allowed(records_on_stdout=False)  # --stats, tables: nothing between
    os.close(r)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: False, raising=False)
    assert not cp.bar_allowed(records_on_stdout=False)


def test_block_position_moves_inside_a_chunk() -> None:
    """The batch reader reads a whole chunk before its first block: the bar follows the blocks
    through the chunk, not the read position (which stood still, then jumped)."""
    from types import SimpleNamespace

    from eyeq_spi.cli_dissect import _BlockPosition

    where = _BlockPosition()
    fa = SimpleNamespace(ftype=[0] * 100)
    assert [where(SimpleNamespace(fa=fa, hi=h), 1000) for h in (25, 50, 100)] == [
        250, 500, 1000]
    fb = SimpleNamespace(ftype=[0] * 10)
    assert where(SimpleNamespace(fa=fb, hi=5), 2000) == 1500


def _stderr_on_pty(argv: list[str], stdout: Any) -> bytes:
    """Run the CLI with stderr on a pseudo-terminal (80x24), stdout as given; what the
    terminal received."""
    import fcntl
    import pty
    import struct
    import termios

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    env = {**os.environ, "COLUMNS": "80", "LINES": "24", "TERM": "xterm"}
    proc = subprocess.Popen([sys.executable, "-m", "eyeq_spi.cli", *argv], stdout=stdout,
                            stderr=slave, stdin=subprocess.DEVNULL, env=env)
    os.close(slave)
    out = b""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        ready, _, _ = select.select([master], [], [], 0.2)
        if ready:
            try:
                data = os.read(master, 65536)
            except OSError:
                break
            if not data:
                break
            out += data
        elif proc.poll() is not None:
            break
    proc.wait(30)
    os.close(master)
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="needs a Linux pty")
def test_dissect_draws_no_bar_while_records_go_to_a_pipe(demo_capture: Path) -> None:
    sink = subprocess.Popen(["cat"], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL)
    assert sink.stdin is not None
    try:
        piped = _stderr_on_pty(["dissect", str(demo_capture)], sink.stdin)
    finally:
        sink.stdin.close()
        sink.wait(30)
    assert b"ETA" not in piped and b"\x1b[" not in piped, piped[:200]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="needs a Linux pty")
def test_dissect_draws_a_bar_when_stdout_is_a_file(demo_capture: Path, tmp_path: Path
                                                   ) -> None:
    with open(tmp_path / "out.txt", "wb") as f:
        shown = _stderr_on_pty(["dissect", str(demo_capture)], f)
    assert b"ETA" in shown and b"dissect demo.pcapng" in shown and b"B/s" in shown, shown[:300]
    assert (tmp_path / "out.txt").stat().st_size > 0
