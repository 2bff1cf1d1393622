"""`eyeq-spi batch DIR --parquet OUT`: one dataset partitioned by capture and message, with the
message counts of `dissect --stats`, in-process, in a process pool and on a Dask LocalCluster of
2 workers; queried with pyarrow and DuckDB as the README shows."""

from __future__ import annotations

import glob
import json
from pathlib import Path

import pytest

from eyeq_spi.capture.pcapng_io import CaptureWriter
from eyeq_spi.cli import main
from tests.test_dissect_engine_fast import BASE, MUTATIONS, Rec

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

pa = pytest.importorskip("pyarrow", reason="the fleet extra (pyarrow) is not installed")
ds = pytest.importorskip("pyarrow.dataset", reason="the fleet extra (pyarrow) is not installed")


def _pcapng(items: list[Rec], path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with CaptureWriter(path) as w:
        for d, t, wire in items:
            w.write(d, t, wire)
    return path


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("fleet")
    _pcapng(BASE, root / "car1" / "mon.pcapng")
    _pcapng(MUTATIONS["drop"](MUTATIONS["flip"](BASE, 40), 120), root / "car2" / "tue.pcapng")
    return root


def _stats(path: Path, capsys: pytest.CaptureFixture[str]) -> dict[str, int]:
    main(["dissect", str(path), "--stats", "--json"])
    s = json.loads(capsys.readouterr().out)
    return {k: v["count"] for k, v in s["messages"].items()}


def _check(out: Path, fleet: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = ds.dataset(out, format="parquet", partitioning="hive")
    for cap in ("car1__mon", "car2__tue"):
        want = _stats(fleet / cap.replace("__", "/").replace("mon", "mon.pcapng")
                      .replace("tue", "tue.pcapng"), capsys)
        t = data.to_table(filter=ds.field("capture") == cap, columns=["message"])
        got: dict[str, int] = {}
        for m in t.column("message").to_pylist():
            m = m.removesuffix(".reply")  # a MESP reply's partition, beside its request's
            got[m] = got.get(m, 0) + 1
        assert got == want


def test_batch_writes_one_partitioned_dataset(fleet: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ds"
    assert main(["batch", str(fleet), "--parquet", str(out)]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert [s["capture"] for s in lines] == ["car1__mon", "car2__tue"]
    assert all(s["error"] is None and s["frames"] > 0 for s in lines)
    _check(out, fleet, capsys)
    duckdb = pytest.importorskip("duckdb", reason="duckdb is not installed")
    rows = duckdb.connect().execute(f"""
        SELECT capture, message, count(*) AS n, bool_or(errors <> '') AS any_error
        FROM read_parquet('{out}/*/*/*.parquet', hive_partitioning = true, union_by_name = true)
        GROUP BY ALL ORDER BY capture, message""").fetchall()  # the README's query
    assert ("car1__mon", "EYEQ_VIS_OBSTACLES_MSG", 8, False) in rows
    paths = glob.glob(f"{out}/capture=*/message=EYEQ_VIS_OBSTACLES_MSG/*.parquet")
    t = ds.dataset(paths, format="parquet", partitioning="hive",
                   partition_base_dir=str(out)).to_table(
        columns=["capture", "time", "visObjects.visObs[0].physicalState.width"])
    want = sum(_stats(p, capsys)["EYEQ_VIS_OBSTACLES_MSG"] for p in sorted(fleet.rglob("*.pcapng")))
    assert t.num_rows == want and set(t.column("capture").to_pylist()) == {"car1__mon",
                                                                          "car2__tue"}


def test_batch_with_a_process_pool_and_a_bad_capture(fleet: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "f"
    for p in fleet.rglob("*.pcapng"):
        dst = root / p.relative_to(fleet)
        dst.parent.mkdir(parents=True, exist_ok=True)
        dst.write_bytes(p.read_bytes())
    data = (root / "car1" / "mon.pcapng").read_bytes()
    at = 0  # the fifth block gets an impossible length
    for _ in range(4):
        at += int.from_bytes(data[at + 4:at + 8], "little")
    (root / "broken.pcapng").write_bytes(data[:at + 4] + b"\xff" * 4 + data[at + 8:])
    # a killed writer's capture: read up to its last whole block, reported, kept
    (root / "cut.pcapng").write_bytes(data[:-77])
    out = tmp_path / "ds"
    assert main(["batch", str(root), "--parquet", str(out), "--jobs", "2"]) == 1
    lines = {s["capture"]: s for s in map(json.loads, capsys.readouterr().out.splitlines())}
    assert "malformed pcapng" in lines["broken"]["error"]
    assert not (out / "capture=broken").exists()
    assert "ignored the last" in lines["cut"]["error"] and lines["cut"]["ignored_bytes"] > 0
    assert (out / "capture=cut").exists() and lines["cut"]["frames"] > 0
    _check(out, root, capsys)


def test_batch_on_a_dask_local_cluster(fleet: Path, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("distributed", reason="the fleet extra (dask[distributed]) is missing")
    out = tmp_path / "ds"
    assert main(["batch", str(fleet), "--parquet", str(out), "--local-cluster", "2"]) == 0
    capsys.readouterr()
    _check(out, fleet, capsys)


def test_batch_usage_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["batch", str(tmp_path), "--parquet", str(tmp_path / "o")]) == 2
    assert "no *.pcapng" in capsys.readouterr().err
    assert main(["batch", str(tmp_path / "nope"), "--parquet", str(tmp_path / "o")]) == 2
    assert main(["batch", str(tmp_path), "--parquet", "o", "--scheduler", "http://x"]) == 2
    assert main(["batch", str(tmp_path), "--parquet", "o", "--jobs", "0"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 3
