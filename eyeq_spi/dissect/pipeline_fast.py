"""``eyeq-spi dissect`` on the fast path (:mod:`.engine_fast`): pcapng and raw files opened
for it, its frame blocks to the writers, and ``--jobs N`` (files dissected in worker processes,
output identical to a serial run).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from typing import IO, Any

import numpy as np

from eyeq_spi.capture.pcapng_fast import Chunk, chunks_from_transfers, pcapng_chunks
from eyeq_spi.capture.pcapng_io import PCAPNG_MAGIC, Tail
from eyeq_spi.dissect.engine_fast import Item, iter_items
from eyeq_spi.dissect.engine_fast_frames import FrameArrays, FrameBlock
from eyeq_spi.dissect.output import TableWriter
from eyeq_spi.dissect.release import Capture, Release, codec_for, with_release
from eyeq_spi.io.plain import InputError, PeekStream, detect, read_raw, sniff_raw


def open_fast(fh: IO[bytes], fmt: str | None, direction: str | None, *, sw: str | None,
              name: str) -> Capture | None:
    """A seekable pcapng or raw file (read from its start) opened for the fast path, its release
    found in the same pass as its transfers (:func:`.release.open_capture`'s order: ``sw``, the
    recorded release, then what the first transfers show); None: the reference reads it (another
    format, stdin, or not a capture: the reference says so in its own words)."""
    try:
        if not fh.seekable():
            return None
        fh.seek(0)
        head = fh.read(4096)
        fh.seek(0)
    except (OSError, ValueError):
        return None
    try:
        kind = fmt or detect(head)
    except InputError:
        return None
    tail = Tail()
    if kind == "pcapng" and head[:4] == PCAPNG_MAGIC:
        chunks = pcapng_chunks(fh, tail=tail)
    elif kind == "raw" and sniff_raw(head) is not None:
        chunks = chunks_from_transfers(read_raw(PeekStream(fh), direction))
    else:
        return None
    release, chunks = with_release(chunks, head, sw, name, Chunk.transfers)
    return Capture(kind, (t for chunk in chunks for t in chunk.transfers()), release, tail,
                   chunks)


def consume(item: FrameBlock, keep: Callable[[dict[str, Any]], bool], plain: bool,
            stats: Any, writers: list[Any], file: str | None = None) -> None:
    """A frame block to ``--stats`` and the writers. ``plain``: no filter is active (every
    record is kept), so frames are counted and printed straight from the arrays. ``file``:
    every record's ``file`` member."""
    if file is not None:
        for _, msg in item.messages:
            msg["file"] = file
    if not plain:
        for record in item.records():
            if file is not None:
                record["file"] = file
            if keep(record):
                stats.add(record)
                for writer in writers:
                    writer.write(record)
        return
    item.add_to(stats)
    for writer in writers:
        if isinstance(writer, TableWriter):
            tables = iter(item.tables)
            nxt = next(tables, None)
            covered = {id(record) for g in item.tables for record in g.covered}
            for index, (_, record) in enumerate(item.messages):
                while nxt is not None and nxt.first == index:  # a group's rows, from its columns
                    writer.write_columns(nxt.name, nxt.columns)
                    nxt = next(tables, None)
                if id(record) not in covered:  # a group's own records: their rows are columns
                    writer.write(record)
            while nxt is not None:  # lean blocks: groups after the last record
                writer.write_columns(nxt.name, nxt.columns)
                nxt = next(tables, None)
        else:
            for record in item.records():
                if file is not None:
                    record["file"] = file
                writer.write(record)


# -- --jobs N -------------------------------------------------------------------------------------
def _compact(block: FrameBlock) -> FrameBlock:
    """The block's rows only, and only the bytes its records read (header and transport)."""
    fa, lo, hi = block.fa, block.lo, block.hi
    source = fa.chunk
    chunk = Chunk(np.ascontiguousarray(source.data[lo:hi, :8]), source.length[lo:hi].copy(),
                  source.time[lo:hi].copy(), source.direction[lo:hi].copy())
    small = FrameArrays(chunk, fa.base + lo, fa.ftype[lo:hi].copy(), fa.num[lo:hi].copy(),
                        fa.rsp[lo:hi].copy(), fa.crc_ok[lo:hi].copy(), fa.d[lo:hi].copy(),
                        fa.fed[lo:hi].copy(), fa.tfill[lo:hi].copy(), fa.r[lo:hi].copy())
    return FrameBlock(small, 0, hi - lo, [(r - lo, m) for r, m in block.messages],
                      block.tables)


def _worker(path: str, fmt: str | None, direction: str | None, sw: str | None,
            fields: str = "dict") -> tuple[list[Item], Release, Tail] | None:
    """One file's items, release and tail; None: not a fast-path input. Errors as a plain
    :class:`InputError` (what the parent prints)."""
    try:
        with open(path, "rb") as fh:
            cap = open_fast(fh, fmt, direction, sw=sw, name=path)
            if cap is None or cap.chunks is None:
                return None
            items = iter_items(cap.chunks, codec=codec_for(cap.release.key), fields=fields)
            return ([_compact(i) if isinstance(i, FrameBlock) else i for i in items],
                    cap.release, cap.tail)
    except InputError as exc:
        raise InputError(str(exc)) from None
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror or exc}") from None


def parallel_items(paths: list[str], jobs: int, fmt: str | None, direction: str | None,
                   sw: str | None, fields: str = "dict"
                   ) -> Iterator[tuple[str, tuple[list[Item], Release, Tail] | None]]:
    """(path, (items, release, tail)) in the order of ``paths``, dissected ``jobs`` files at a
    time in worker processes; None: the file is not a fast-path input (the caller runs the
    reference path). At most ``jobs`` finished files wait in memory ahead of the one being
    written."""
    from concurrent.futures import ProcessPoolExecutor  # 6 ms of start-up a serial run saves

    with ProcessPoolExecutor(max_workers=jobs) as pool:
        pending: list[Any] = [pool.submit(_worker, p, fmt, direction, sw, fields)
                              for p in paths[:jobs]]
        for index, path in enumerate(paths):
            done = pending[index].result()
            if len(pending) < len(paths):
                pending.append(pool.submit(_worker, paths[len(pending)], fmt, direction, sw,
                                           fields))
            pending[index] = None
            yield path, done


def default_jobs() -> int:
    with contextlib.suppress(AttributeError):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1
