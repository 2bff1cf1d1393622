"""`eyeq-spi dissect` on the fast path prints what the exact path prints (--json, --stats,
--csv, --parquet, filters), and `--jobs N` prints what a serial run prints."""

from __future__ import annotations

import io
import sys
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.capture.pcapng_io import CaptureWriter
from eyeq_spi.cli import main
from tests.test_dissect_engine_fast import BASE, MUTATIONS, Rec


def _pcapng(items: list[Rec], path: Path) -> Path:
    with CaptureWriter(path) as w:
        for d, t, wire in items:
            w.write(d, t, wire)
    return path


@pytest.fixture(scope="module")
def captures(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    tmp = tmp_path_factory.mktemp("caps")
    faulty = BASE
    for name, where in (("flip", 30), ("drop", 90), ("dup", 120), ("late", 200),
                        ("short", 260), ("reset", 300)):
        faulty = MUTATIONS[name](faulty, where)
    raw = tmp / "e2h.bin"
    raw.write_bytes(b"".join(w for d, _, w in BASE if d == "e2h"))
    return [_pcapng(BASE, tmp / "clean.pcapng"), _pcapng(faulty, tmp / "faulty.pcapng"), raw]


class _Pipe(io.RawIOBase):
    """A stdin that cannot seek, as a pipe: the exact path reads it."""

    def __init__(self, data: bytes) -> None:
        self.src = io.BytesIO(data)

    def readable(self) -> bool:
        return True

    def readinto(self, b: Any) -> int:
        chunk = self.src.read(len(b))
        b[: len(chunk)] = chunk
        return len(chunk)


def _exact(args: list[str], data: bytes, capsys: pytest.CaptureFixture[str],
           monkeypatch: pytest.MonkeyPatch) -> tuple[int, str]:
    capsys.readouterr()
    with monkeypatch.context() as m:
        m.setattr(sys, "stdin", io.TextIOWrapper(io.BufferedReader(_Pipe(data))))
        rc = main(args)
    return rc, capsys.readouterr().out


@pytest.mark.parametrize("mode", [["--json"], ["--stats", "--json"], [],
                                  ["--json", "--errors-only"], ["--json", "--protocol", "MESP"]])
def test_file_and_stdin_print_the_same(captures: list[Path], mode: list[str],
                                       capsys: pytest.CaptureFixture[str],
                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """A file takes the fast path; stdin cannot seek and takes the exact one."""
    for path, extra in ((captures[1], []), (captures[2], ["--direction", "e2h"])):
        capsys.readouterr()
        rc = main(["dissect", str(path), *extra, *mode])
        batch_out = capsys.readouterr().out.replace(str(path), "-")  # every record's file
        assert (rc, batch_out) == _exact(["dissect", "-", *extra, *mode], path.read_bytes(),
                                         capsys, monkeypatch)


def test_tables_from_both_paths(captures: list[Path], tmp_path: Path,
                                capsys: pytest.CaptureFixture[str],
                                monkeypatch: pytest.MonkeyPatch) -> None:
    main(["dissect", str(captures[1]), "--csv", str(tmp_path / "b")])
    _exact(["dissect", "-", "--csv", str(tmp_path / "e")], captures[1].read_bytes(), capsys,
           monkeypatch)
    names = sorted(p.name for p in (tmp_path / "e").iterdir())
    assert names and names == sorted(p.name for p in (tmp_path / "b").iterdir())
    for n in names:  # the file column names the file, or - for stdin
        got = (tmp_path / "b" / n).read_bytes().replace(str(captures[1]).encode(), b"-")
        assert got == (tmp_path / "e" / n).read_bytes()


def test_jobs_prints_what_a_serial_run_prints(captures: list[Path],
                                              capsys: pytest.CaptureFixture[str]) -> None:
    files = [str(p) for p in captures[:2]] * 2
    for mode in (["--json"], ["--stats", "--json"]):
        rc1 = main(["dissect", *files, *mode])
        serial = capsys.readouterr().out
        rc2 = main(["dissect", "--jobs", "2", *files, *mode])
        assert (rc2, capsys.readouterr().out) == (rc1, serial)


def test_jobs_errors(captures: list[Path], tmp_path: Path,
                     capsys: pytest.CaptureFixture[str]) -> None:
    data = captures[0].read_bytes()
    bad = tmp_path / "bad.pcapng"
    at = 0  # the first Enhanced Packet Block gets an impossible length
    while int.from_bytes(data[at:at + 4], "little") != 6:
        at += int.from_bytes(data[at + 4:at + 8], "little")
    bad.write_bytes(data[:at + 4] + (13).to_bytes(4, "little") + data[at + 8:])
    assert main(["dissect", "--jobs", "2", str(captures[0]), str(bad), "--stats"]) == 2
    err = capsys.readouterr().err
    assert "malformed pcapng" in err and err.count("\n") == 1
    cut = tmp_path / "cut.pcapng"  # a killed writer's file: read up to its last whole block
    cut.write_bytes(data[:-77])
    assert main(["dissect", "--jobs", "2", str(captures[0]), str(cut), "--stats"]) == 1
    err = capsys.readouterr().err
    assert "ignored the last" in err and err.count("\n") == 1
    assert main(["dissect", "--jobs", "-1", str(captures[0]), str(captures[0])]) == 2
