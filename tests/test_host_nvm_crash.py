"""NVM crash test: 200 ``kill -9`` of a process writing the NVM through
``eyeq_spi.host.nvm``'s atomic writer. The NVM file must never be corrupt (it is always one
complete version), and once the host's start-up cleanup has run no temporary file is left."""

from __future__ import annotations

import json
import multiprocessing
import os
import random
import signal
import time
from pathlib import Path

import pytest

from eyeq_spi.host.nvm import Nvm

KILLS = int(os.environ.get("EYEQ_NVM_KILLS", "200"))  # more in a long run (docs/development.md)
pytestmark = pytest.mark.realtime


def _writer(path: str, first: int) -> None:
    nvm = Nvm(path)
    n = first
    while True:
        n += 1
        nvm.data.ignition_cycles = n
        # every value carries the version, so a torn file cannot pass for a whole one
        nvm.data.intrinsic = {f"p{i:02d}": float(n) for i in range(60)}
        nvm.save()


def _check(path: Path) -> int | None:
    """The version in the NVM file (None before the first complete write); fails if torn."""
    if not path.exists():
        return None
    doc = json.loads(path.read_text(encoding="utf-8"))
    n = doc["ignition_cycles"]
    assert set(doc["intrinsic"].values()) == {float(n)}, f"torn NVM at version {n}"
    return int(n)


def _kill_writers(path: Path) -> tuple[list[int | None], int]:
    ctx = multiprocessing.get_context("fork")  # no re-import: the kill lands in the write loop
    rng = random.Random(9)
    versions: list[int | None] = []
    mid_write = 0
    for i in range(KILLS):
        p = ctx.Process(target=_writer, args=(str(path), i * 1_000_000))
        p.start()
        time.sleep(rng.uniform(0.001, 0.006))  # bounded wall time: the kill must hit a write
        assert p.pid is not None
        os.kill(p.pid, signal.SIGKILL)
        p.join(5)
        assert p.exitcode == -signal.SIGKILL
        versions.append(_check(path))
        mid_write += any(q.name != path.name for q in path.parent.iterdir())
    return versions, mid_write


@pytest.fixture(scope="module")
def killed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[int | None], int]:
    path = tmp_path_factory.mktemp("nvm") / "nvm.json"
    versions, mid_write = _kill_writers(path)
    return path, versions, mid_write


def test_200_kills_never_leave_a_corrupt_nvm(killed: tuple[Path, list[int | None], int]
                                            ) -> None:
    path, versions, _ = killed
    written = [v for v in versions if v is not None]
    assert len(written) >= KILLS // 2, "the writers hardly ever completed a write"
    # after each kill the file holds the last complete version written so far, never older
    assert written == sorted(written)
    assert all(v // 1_000_000 <= i for i, v in enumerate(versions) if v is not None)
    nvm = Nvm(path)
    nvm.load()
    assert nvm.load_problem is None and nvm.data.ignition_cycles == written[-1]


def test_start_up_leaves_no_temp_file_after_200_kills(
        killed: tuple[Path, list[int | None], int]) -> None:
    path, _, mid_write = killed
    assert mid_write > 0, "no kill landed inside a write: the test proves nothing"
    # before the fix of defect 6 (8db4c39) about 90 temp files were left here
    Nvm(path).load()  # the host's start-up
    assert sorted(p.name for p in path.parent.iterdir()) == [path.name]
