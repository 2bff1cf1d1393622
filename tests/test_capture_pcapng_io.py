"""A capture survives a crash: the writer puts whole blocks on disk, at least once a second, and
every reader reads a file cut inside a block up to its last whole block, says in one line how
many bytes it ignored, and exits 1."""

from __future__ import annotations

import io
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from eyeq_spi.capture.pcapng_fast import pcapng_chunks
from eyeq_spi.capture.pcapng_io import CaptureWriter, Tail, read_pcapng
from eyeq_spi.cli import main
from eyeq_spi.dissect.pipeline import SMALL_INPUT
from eyeq_spi.errors import InputError
from eyeq_spi.io.plain import open_transfers
from tests.waiting import wait_until

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

WRITER = """
import itertools, sys
from eyeq_spi.capture.pcapng_io import CaptureWriter
w = CaptureWriter(sys.argv[1], "8.1")
print("ready", flush=True)
for i in itertools.count():
    w.write("h2e" if i % 2 else "e2h", i * 1e-4, bytes([i & 0xFF]) * (100 if i % 50 == 7 else 128))
"""


def _both(data: bytes) -> tuple[list[tuple[float | None, str | None, bytes]], Tail, Tail]:
    """The transfers the exact and the batch reader take from ``data``; they must agree."""
    t1, t2 = Tail(), Tail()
    exact = [(r.time, r.direction, r.data) for r in read_pcapng(io.BytesIO(data), t1)]
    batch = []
    for c in pcapng_chunks(io.BytesIO(data), tail=t2):
        for i in range(len(c)):
            r = c.transfer(i)
            batch.append((r.time, r.direction, r.data))
    assert exact == batch and t1 == t2
    return exact, t1, t2


def _boundaries(data: bytes) -> list[int]:
    out, at = [], 0
    while at < len(data):
        at += int.from_bytes(data[at + 4:at + 8], "little")
        out.append(at)
    return out


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    path = tmp_path_factory.mktemp("crash") / "good.pcapng"
    with CaptureWriter(path, "8.1") as w:
        for i in range(40):
            w.write("h2e" if i % 2 else "e2h", i * 1e-3, bytes([i]) * (100 if i % 9 == 4 else 128))
    return path.read_bytes()


def test_every_cut_reads_up_to_the_last_whole_block(good: bytes) -> None:
    full, tail, _ = _both(good)
    assert len(full) == 40 and tail.ignored == 0
    bounds = _boundaries(good)
    first_epb = bounds[2]  # SHB, two IDBs
    for b in bounds:
        for delta in range(-5, 6):
            cut = b + delta
            if not first_epb < cut <= len(good):
                continue
            if cut < bounds[3]:  # not one whole transfer: still a bad input (exit 2)
                with pytest.raises(InputError, match="without any transfer"):
                    list(open_transfers(io.BytesIO(good[:cut]), tail=Tail())[1])
                with pytest.raises(InputError, match="without any transfer"):
                    list(pcapng_chunks(io.BytesIO(good[:cut]), tail=Tail()))
                continue
            got, tail, _ = _both(good[:cut])
            whole = max(x for x in [0, *bounds] if x <= cut)
            n = sum(1 for x in bounds[3:] if x <= cut)
            assert got == full[:n], cut
            assert (tail.ignored, tail.at if tail.ignored else whole) == (cut - whole, whole)


def test_the_cli_readers_say_it_in_one_line_and_exit_1(good: bytes, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    cut = tmp_path / "cut.pcapng"
    cut.write_bytes(good[:-8])  # 8 bytes into the last block, as the killed demo left it
    big = tmp_path / "big.pcapng"  # big enough for dissect's fast path
    with CaptureWriter(big, "8.1") as w:
        for i in range(SMALL_INPUT // 160 + 10):
            w.write("h2e" if i % 2 else "e2h", i * 1e-3, bytes([i & 0xFF]) * 128)
    big.write_bytes(big.read_bytes()[:-8])
    assert big.stat().st_size >= SMALL_INPUT
    for path in (str(cut), str(big)):  # the references, and the fast path
        for argv in (["dissect", path, "--json"], ["dissect", path, "--stats"],
                     ["dissect", "-j", "2", path, path, "--stats", "--json"]):
            capsys.readouterr()
            rc = main(argv)
            out, err = capsys.readouterr()
            lines = err.splitlines()
            assert rc == 1 and out and len(lines) == argv.count(path), (argv, err)
            assert all("ignored the last" in x and "Traceback" not in x for x in lines)
    bounds = _boundaries(good)
    left = len(good) - 8 - bounds[-2]  # the last block, but for the 8 bytes cut off
    others = [["replay", str(cut), "--into-host", "--json"],
              ["monitor", "--replay", str(cut), "--pace", "0"],
              ["monitor", "--replay", str(cut), "--passive", "--pace", "0"]]
    import importlib.util

    if importlib.util.find_spec("mcap") is not None:
        others.append(["export", str(cut), "--mcap", str(tmp_path / "x.mcap")])
    if importlib.util.find_spec("matplotlib") is not None:
        others.append(["plot", str(cut), "--link", "-o", str(tmp_path / "l.png")])
    for argv in others:
        capsys.readouterr()
        rc = main(argv)
        err = capsys.readouterr().err
        assert rc == 1 and err.count("\n") == 1 and "Traceback" not in err, argv
        assert f"ignored the last {left} bytes" in err, argv


def test_a_writer_flushes_whole_blocks_at_least_once_a_second(tmp_path: Path) -> None:
    now = [0.0]
    path = tmp_path / "w.pcapng"
    w = CaptureWriter(path, clock=lambda: now[0], idle_flush=False)
    head = path.stat().st_size
    assert head > 0  # the header blocks are on disk at once
    w.write("h2e", 0.0, bytes(128))
    assert path.stat().st_size == head  # buffered
    now[0] = 1.0
    w.write("e2h", 0.5, bytes(128))
    size = path.stat().st_size
    assert size > head and _both(path.read_bytes())[1].ignored == 0
    w.close()
    assert path.stat().st_size == size


def test_an_idle_writer_flushes_too(tmp_path: Path) -> None:
    """No transfer after the last one (a vanished peer): the waiting blocks still reach the
    file within the flush interval (bounded wall time: a thread of the writer does it)."""
    path = tmp_path / "idle.pcapng"
    w = CaptureWriter(path, flush_s=0.05)
    try:
        head = path.stat().st_size
        w.write("h2e", 0.0, bytes(128))
        wait_until(lambda: path.stat().st_size != head, 20, "the idle writer flushed")
        assert path.stat().st_size == head + 160 + 24  # the first packet, with its comment
    finally:
        w.close()


def test_a_writer_killed_at_random_instants_leaves_a_readable_capture(tmp_path: Path) -> None:
    """SIGKILL at random points of a subprocess writing as fast as it can (bounded: 20 runs).
    The writer hands the file whole blocks only; the kernel may still cut its last write when
    the process is killed in the middle of it, so the reader may leave less than one flush."""
    import numpy as np

    rng = random.Random(20)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    for run in range(20):
        path = tmp_path / f"k{run}.pcapng"
        proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], env=env,
                                stdout=subprocess.PIPE, text=True)
        try:
            assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
            time.sleep(rng.uniform(0.0, 0.15))  # a random instant of the writer's run
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=30)
            if proc.stdout is not None:
                proc.stdout.close()
        tail = Tail()
        with path.open("rb") as fh:
            chunks = list(pcapng_chunks(fh, tail=tail))
        assert tail.ignored < CaptureWriter.FLUSH_BYTES + 160, run
        n = sum(len(c) for c in chunks)
        i = np.arange(n)
        times = np.concatenate([c.time for c in chunks])
        dirs = np.concatenate([c.direction for c in chunks])
        lengths = np.concatenate([c.length for c in chunks])
        data = np.concatenate([c.data for c in chunks])
        # every transfer written, in order, intact
        assert np.allclose(times, i * 1e-4) and (dirs == 1 - i % 2).all(), run  # e2h first
        assert (lengths == np.where(i % 50 == 7, 100, 128)).all(), run
        full = lengths == 128
        assert (data[full] == (i[full] & 0xFF)[:, None]).all(), run


def test_a_killed_demo_dissects_clean(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                      ) -> None:
    """``demo --capture`` killed with SIGKILL in the middle of its run."""
    path = tmp_path / "demo.pcapng"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.Popen([sys.executable, "-m", "eyeq_spi.cli", "demo", "--duration", "60",
                             "--capture", str(path)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        wait_until(lambda: path.exists() and path.stat().st_size >= 100_000, 60,
                   "100 kB of capture written")
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    assert path.stat().st_size >= 100_000
    capsys.readouterr()
    rc = main(["dissect", str(path), "--stats"])
    out, err = capsys.readouterr()
    assert (rc, err) == (0, ""), out
