"""The terminal side of the CLI: human dissect lines (time since the first transfer, direction),
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
    """``dissect --id 0xE4``: every line says when (s since the capture's first transfer, the
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
    from eyeq_spi.cli import progress as cp

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

    from eyeq_spi.dissect.pipeline import BlockPosition as _BlockPosition

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


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="needs a Linux pty")
def test_dissect_draws_one_bar_per_file(demo_capture: Path, tmp_path: Path) -> None:
    """A file's bar runs once from 0 to 100 %: the calls about a file after its bar ended (the
    statistics' last pass) draw no second one."""
    with open(tmp_path / "out.txt", "wb") as f:
        shown = _stderr_on_pty(["dissect", str(demo_capture), "--stats"], f)
    assert shown.count(b"\x1b[?25l") == 1, shown  # rich hides the cursor once per bar


def test_dissect_jobs_draws_a_bar_over_the_files(demo_capture: Path, tmp_path: Path) -> None:
    """``--jobs``: the files are decoded in workers, so the bar counts files."""
    import shutil

    b = tmp_path / "b.pcapng"
    shutil.copy(demo_capture, b)
    with open(tmp_path / "out.txt", "wb") as f:
        shown = _stderr_on_pty(["dissect", str(demo_capture), str(b), "--jobs", "2",
                                "--stats"], f)
    assert b"dissect 2 files" in shown and b"files" in shown, shown[:300]
    assert b"total" in (tmp_path / "out.txt").read_bytes()


def _all_parsers() -> list[tuple[str, Any]]:
    import argparse

    from eyeq_spi.cli import build_parser
    from eyeq_spi.cli.help import finish

    top = build_parser()
    finish(top)
    out: list[tuple[str, Any]] = []

    def walk(p: Any, name: str) -> None:
        out.append((name, p))
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for n, sub in a.choices.items():
                    walk(sub, f"{name} {n}".strip())

    walk(top, "")
    return out


def test_every_help_has_a_description_and_examples_that_parse(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import shlex

    from eyeq_spi.cli import build_parser

    monkeypatch.chdir(tmp_path)
    for f in ("capture.pcapng", "drive.blf", "drive.asc", "x.pcapng", "vendor.dbc"):
        (tmp_path / f).write_bytes(b"")
    parsers = _all_parsers()
    assert len(parsers) >= 19  # the top level, 14 commands, can's and spec's subcommands
    for name, p in parsers:
        text = p.format_help()
        assert p.description and len(p.description) > 20, name
        examples = text.split("\nexamples:\n", 1)[1].splitlines()
        assert 2 <= len(examples) <= 3, (name, examples)
        for line in examples:
            cmd = line.split(" && ")[0].split(" | ")[0].split("  #")[0].strip()
            if not cmd.startswith("eyeq-spi ") or "COMMAND" in cmd:
                continue
            argv = shlex.split(cmd)[1:]
            assert build_parser().parse_args(argv), (name, cmd)
    top = parsers[0][1].format_help()
    assert "EyeqError" not in top and "traceback" not in top  # no developer docstring


def test_bare_command_prints_the_command_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 0
    out = capsys.readouterr().out
    assert "commands:" in out and "dissect" in out and "examples:" in out
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and re.match(r"eyeq-spi \d+\.\d+", capsys.readouterr().out)


def test_bash_completion_completes_commands_and_options(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    pytest.importorskip("shtab", reason="shell completion needs shtab")
    assert main(["--print-completion", "bash"]) == 0
    script = tmp_path / "eyeq-spi.bash"
    script.write_text(capsys.readouterr().out)
    probe = (f"source {script}; COMP_WORDS=(eyeq-spi dis); COMP_CWORD=1; _shtab_eyeq_spi; "
             "echo \"${COMPREPLY[@]}\"; COMP_WORDS=(eyeq-spi dissect --sta); COMP_CWORD=2; "
             "_shtab_eyeq_spi; echo \"${COMPREPLY[@]}\"")
    r = subprocess.run(["bash", "-c", probe], capture_output=True, text=True, timeout=60)
    assert r.stdout.split("\n")[:2] == ["dissect", "--stats"], r
    assert main(["--print-completion", "fish"]) == 2


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="needs a Linux pty")
def test_a_long_demo_shows_a_bar_below_its_live_lines() -> None:
    shown = _stderr_on_pty(["demo", "--virtual-time", "--duration", "20"], subprocess.DEVNULL)
    assert b"ETA" in shown and b"s of run time" in shown
    assert b"--RUNNING_VISION--> RUNNING_VISION" in shown  # the live lines still print


def test_batch_reports_each_capture_done(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                         ) -> None:
    pytest.importorskip("pyarrow", reason="batch needs the parquet extra")
    from eyeq_spi.dissect import fleet

    for name in ("a", "b", "c"):
        (tmp_path / f"{name}.pcapng").write_bytes(b"")
    monkeypatch.setattr(fleet, "dissect_capture",
                        lambda path, out, key, sw: {"capture": key, "error": None})
    seen: list[tuple[int, int]] = []
    fleet.run_fleet(str(tmp_path), str(tmp_path / "out"), progress=lambda d, t: seen.append(
        (d, t)))
    assert seen == [(0, 3), (1, 3), (2, 3), (3, 3)]


def test_conformance_reports_its_steps() -> None:
    """The bar's total is known up front: the sessions to run, then the judging."""
    from eyeq_spi.conformance.suite import Options, run

    seen: list[tuple[int, int]] = []
    results = run(Options(dut="eyeq", builtin=True, steps=lambda d, t: seen.append((d, t))))
    assert seen == [(0, 2), (1, 2), (2, 2)] and results
