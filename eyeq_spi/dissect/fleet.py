"""Many captures into one partitioned Parquet dataset (``eyeq-spi batch``).

Each capture goes through the pipeline into the tables of ``dissect --parquet`` (with an
``errors`` column, without ``file``) under ``OUT/capture=<capture>/message=<name>/``: one
Hive-partitioned dataset for pyarrow, DuckDB or pandas. Tasks run in this process, a process
pool, or on Dask (``distributed``; its workers must see the same paths). A capture that cannot
be read becomes an ``error`` in its summary and has no partition.
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from eyeq_spi.errors import AdapterError, EyeqError, InputError, MissingExtra, OutputError

ROWS_PER_GROUP = 4096


def find_captures(root: str | Path) -> list[Path]:
    """Every ``*.pcapng`` under ``root`` (sorted), or ``root`` itself if it is one."""
    path = Path(root)
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise InputError(f"{root}: no such directory")
    found = sorted(q for q in path.rglob("*.pcapng") if q.is_file())
    if not found:
        raise InputError(f"{root}: no *.pcapng capture in it")
    return found


def capture_key(path: Path, root: Path) -> str:
    """The capture's partition value: its path under ``root`` without the suffix, with
    separators and anything unsafe in a directory name replaced."""
    try:
        rel = path.relative_to(root) if root.is_dir() else Path(path.name)
    except ValueError:
        rel = Path(path.name)
    return re.sub(r"[^A-Za-z0-9._-]+", "_", str(rel.with_suffix("")).replace(os.sep, "__"))


def _pyarrow() -> tuple[Any, Any]:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as exc:
        raise MissingExtra("fleet", "eyeq-spi batch needs pyarrow") from exc
    return pa, pq


def dissect_capture(path: str, out: str, capture: str, sw: str | None = None
                    ) -> dict[str, Any]:
    """One task: ``path`` through the pipeline into the tables of
    ``out/capture=<capture>/message=<name>/part-N.parquet``. Returns a JSON-ready summary (never
    raises for a bad capture)."""
    from eyeq_spi.catalog.messages import catalog
    from eyeq_spi.dissect.output import TableWriter
    from eyeq_spi.dissect.pipeline import DissectConfig, deliver, dissect_captures
    from eyeq_spi.dissect.stats import Stats

    _pyarrow()
    summary: dict[str, Any] = {"capture": capture, "path": path, "frames": 0, "messages": {},
                               "events": 0, "error": None}
    base = Path(out) / f"capture={capture}"
    stats = Stats(catalog(), file=path)
    writer: TableWriter | None = None
    config = DissectConfig(fmt="pcapng", sw=sw, fields="dict", blocks=True)
    try:
        for cf in dissect_captures([path], config):
            summary.update(cf.release.as_dict())
            if cf.release.warning:
                summary["warning"] = cf.release.warning
            writer = TableWriter(str(base), "parquet", ROWS_PER_GROUP, errors=True, hive=True)
            deliver(cf.items, stats, [writer], path=path)
            if cf.tail.ignored:  # the dataset keeps what was whole; the summary says what not
                summary["ignored_bytes"] = cf.tail.ignored
                summary["error"] = cf.tail.note(path)
                summary["partial"] = True
    except (EyeqError, OSError) as exc:
        summary["error"] = str(exc)
    finally:
        if writer is not None:
            writer.close()
    summary["frames"] = sum(stats.frames.values())
    summary["messages"] = dict(stats.messages)
    summary["events"] = sum(stats.events.values())
    if summary["error"] is not None and not summary.get("partial"):  # whole captures only
        shutil.rmtree(base, ignore_errors=True)
    return summary


def run_fleet(root: str, out: str, *, sw: str | None = None, jobs: int = 1,
              scheduler: str | None = None, local_cluster: int | None = None,
              progress: Callable[[int, int], None] | None = None) -> list[dict[str, Any]]:
    """Every capture under ``root`` into the dataset ``out``; one summary per capture, in the
    order of the captures. ``progress(done, total)``: captures finished so far (in this
    process and the local pool; Dask reports at the end)."""
    _pyarrow()
    paths = find_captures(root)
    rootp = Path(root)
    tasks = [(str(p.resolve()), capture_key(p, rootp)) for p in paths]
    keys = [k for _, k in tasks]
    if len(set(keys)) != len(keys):
        raise InputError("two captures map to the same partition name")
    try:
        Path(out).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create {out}: {exc}") from exc
    outp = str(Path(out).resolve())
    count = len(tasks)
    tick = progress or (lambda done, total: None)
    tick(0, count)
    if scheduler or local_cluster:
        results = _on_dask(tasks, outp, sw, scheduler, local_cluster)
        tick(count, count)
        return results
    if jobs > 1 and count > 1:
        from concurrent.futures import as_completed

        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futs = [pool.submit(dissect_capture, p, outp, k, sw) for p, k in tasks]
            for done, _ in enumerate(as_completed(futs), 1):
                tick(done, count)
            return [f.result() for f in futs]
    results = []
    for path, key in tasks:
        results.append(dissect_capture(path, outp, key, sw))
        tick(len(results), count)
    return results


def _on_dask(tasks: list[tuple[str, str]], out: str, sw: str | None, scheduler: str | None,
             local_cluster: int | None) -> list[dict[str, Any]]:
    try:
        import importlib

        dd: Any = importlib.import_module("distributed")  # partly typed: used as Any
        Client, LocalCluster = dd.Client, dd.LocalCluster
    except ImportError as exc:
        raise InputError("--scheduler/--local-cluster need Dask: "
                         "pip install 'eyeq-spi[fleet]'") from exc
    cluster = None
    try:
        if scheduler:
            client = Client(scheduler, timeout="10s")
        else:
            cluster = LocalCluster(n_workers=local_cluster, threads_per_worker=1,
                                   processes=True, dashboard_address=None)
            client = Client(cluster)
    except (OSError, TimeoutError) as exc:
        raise AdapterError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None
    try:
        futs = [client.submit(dissect_capture, p, out, k, sw, key=f"eyeq-spi-{k}", pure=False)
                for p, k in tasks]
        return list(client.gather(futs))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
