"""Every message is a row: the tables of ``dissect --csv``/``--parquet`` hold as many rows per
message as ``dissect --stats`` counts (a MESP request without parameters included), on the fast
path (a file big enough for it) and on the reference (``EYEQ_SPI_EXACT=1``)."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from eyeq_spi.cli import main

CLI = [sys.executable, "-m", "eyeq_spi.cli"]
pytestmark = pytest.mark.twin


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three seconds of demo traffic: bring-up MESP requests without parameters among them."""
    path = tmp_path_factory.mktemp("cap") / "demo.pcapng"
    r = subprocess.run([*CLI, "demo", "--virtual-time", "--duration", "3", "--capture",
                        str(path)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert path.stat().st_size > 256 << 10  # the fast path takes it
    return path


def _stats(capture: Path, capsys: pytest.CaptureFixture[str]) -> dict[str, int]:
    main(["dissect", str(capture), "--stats", "--json"])
    out = json.loads(capsys.readouterr().out)
    return {k: v["count"] for k, v in out["messages"].items()}


def _per_message(rows: Counter[str]) -> dict[str, int]:
    """Table row counts by message: a MESP reply's table ``NAME.reply`` counts for NAME."""
    out: Counter[str] = Counter()
    for table, n in rows.items():
        out[table.removesuffix(".reply")] += n
    return dict(out)


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_every_message_is_a_row(capture: Path, tmp_path: Path, fmt: str,
                                capsys: pytest.CaptureFixture[str]) -> None:
    if fmt == "parquet":
        pq = pytest.importorskip("pyarrow.parquet", reason="--parquet needs pyarrow")
    want = _stats(capture, capsys)
    assert want.get("GetEyeQExtendedState")  # a request without parameters is among them
    out = tmp_path / fmt
    main(["dissect", str(capture), f"--{fmt}", str(out)])
    rows: Counter[str] = Counter()
    for path in out.iterdir():
        table = path.name.removesuffix(f".{fmt}")
        if fmt == "csv":
            with open(path, newline="", encoding="utf-8") as fh:
                rows[table] += sum(1 for _ in csv.DictReader(fh))
        else:
            rows[table] += pq.read_metadata(path).num_rows
    assert _per_message(rows) == want


def test_reference_tables_agree(capture: Path, tmp_path: Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    """The same CSV tables, cell for cell, from the reference dissector."""
    fast = tmp_path / "fast"
    main(["dissect", str(capture), "--csv", str(fast)])
    env = {**os.environ, "EYEQ_SPI_EXACT": "1"}
    ref = tmp_path / "ref"
    subprocess.run([*CLI, "dissect", str(capture), "--csv", str(ref)], env=env, check=True,
                   stdout=subprocess.DEVNULL, timeout=300)
    names = sorted(p.name for p in fast.iterdir())
    assert names == sorted(p.name for p in ref.iterdir())
    for name in names:
        assert (fast / name).read_text() == (ref / name).read_text(), name
