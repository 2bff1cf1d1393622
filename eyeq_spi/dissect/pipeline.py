"""Captures in, dissector records out: the one pipeline behind ``dissect``, ``plot``, ``monitor``,
``export`` and ``replay``.

Every reader of captures opens them here, so each reads every input format, each capture with
its own SW release (:mod:`.release`), a pcapng file cut inside a block up to its last whole
block (:attr:`CaptureFile.tail`), and gets the fast path where it applies: a seekable pcapng or
raw file of at least :data:`SMALL_INPUT` bytes (:mod:`.pipeline_fast`), else the reference
(:class:`.engine.Dissector`), with the same records; with ``jobs`` > 1 files are dissected in
worker processes, in the order given.

:func:`dissect_files` hands out plain records (each with its ``file``); :func:`dissect_captures`
one :class:`CaptureFile` per file (the release before the records, or the fast path's frame
blocks whole); :func:`open_capture_file` one capture for its transfers.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import IO, Any

from eyeq_spi import garbage
from eyeq_spi.capture.pcapng_io import Tail, Transfer
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect.release import Capture, Release, codec_for, open_capture
from eyeq_spi.errors import EyeqError
from eyeq_spi.io import can_log_hint
from eyeq_spi.io.plain import InputError
from eyeq_spi.logic.options import SpiOptions
from eyeq_spi.twins import references_only

SMALL_INPUT = 256 << 10  # bytes; below this the reference is quicker than importing numpy
PACE = 4096  # records between two looks at the young generation
YOUNG = 20_000  # containers it must have grown by to be collected

AUTO = "auto"

Progress = Callable[[str | None, float, float | None], None]
"""``progress(path, done, total)``: ``done`` of ``total`` bytes of the file ``path`` read (a
file read in this process, when its size is known), or with ``path`` None, ``done`` of
``total`` files finished (files dissected in worker processes)."""


@dataclass(frozen=True)
class DissectConfig:
    """How captures are read: the input format (None: detect it), the channel of a raw or hex
    file, the logic-analyzer options, the release (None: each capture's own), files at a time
    (0: one per CPU), what the fast path's messages carry (:func:`fields_mode`), frame blocks
    handed out whole (:func:`.pipeline_fast.consume`), and whether collections are paced
    (:func:`paced_gc`; off for a consumer that holds the iterator long, a live view)."""

    fmt: str | None = None
    direction: str | None = None
    spi: SpiOptions | None = None
    sw: str | None = None
    jobs: int = 1
    fields: str = "dict"
    blocks: bool = False
    pace_gc: bool = True


def open_stream(path: str) -> IO[bytes]:
    """The file ``path`` for reading, or stdin for ``-``."""
    if path == "-":
        return sys.stdin.buffer
    try:
        return open(path, "rb")
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror or exc}") from None


@dataclass
class CaptureFile:
    """One capture of the pipeline: its path, the release it is read with, its dissected
    ``items`` (records, or frame blocks with :attr:`DissectConfig.blocks`), or its raw
    ``transfers`` (one or the other), and what its reader ignored at its end (:attr:`tail`,
    filled once the items or transfers are exhausted). The file is opened at the first look at
    :attr:`release`, :attr:`items` or :attr:`transfers`."""

    path: str
    config: DissectConfig = field(default_factory=DissectConfig)
    fast: Any = None  # eyeq_spi.dissect.pipeline_fast when the fast path may be taken, AUTO:
    # when the file is big enough (fast_module)
    progress: Progress | None = None
    _done: tuple[list[Any], Release, Tail] | None = None  # from a worker process
    _fh: IO[bytes] | None = None
    _cap: Capture | None = None

    def open(self) -> Capture:
        if self._cap is None:
            cfg = self.config
            self._fh = open_stream(self.path)
            try:
                fast = fast_module([self.path]) if self.fast is AUTO else self.fast
                cap = (fast.open_fast(self._fh, cfg.fmt, cfg.direction, sw=cfg.sw,
                                      name=self.path) if fast is not None else None)
                self._cap = cap or open_capture(self._fh, cfg.fmt, cfg.direction, cfg.spi,
                                                sw=cfg.sw, name=self.path)
            except EyeqError as exc:
                self.close()
                raise _naming(exc, self.path) from None
            except BaseException:
                self.close()
                raise
        return self._cap

    @property
    def release(self) -> Release:
        if self._done is not None:
            return self._done[1]
        return self.open().release

    @property
    def tail(self) -> Tail:
        if self._done is not None:
            return self._done[2]
        return self.open().tail

    @property
    def codec(self) -> MessageCodec:
        return codec_for(self.release.key)

    @property
    def transfers(self) -> Iterator[Transfer]:
        """The capture's transfers as read (no dissection)."""
        return self.open().transfers

    @property
    def items(self) -> Iterator[Any]:
        """The dissector's records in order (with :attr:`DissectConfig.blocks`, the fast
        path's frame blocks whole, the other records as dicts), GC paced when configured."""
        items = self._items()
        return self._expand(paced_gc(items) if self.config.pace_gc else items)

    def _items(self) -> Iterator[Any]:
        if self._done is not None:
            yield from self._done[0]
            return
        from eyeq_spi.dissect.engine import iter_records

        cap = self.open()
        fh = self._fh
        assert fh is not None
        try:
            if cap.chunks is not None:  # opened by the fast path (open): numpy is loaded
                from eyeq_spi.dissect.engine_fast import iter_items

                items = iter_items(cap.chunks, codec=self.codec, fields=self.config.fields)
            else:
                items = iter_records(cap.transfers, codec=self.codec)
            yield from self._tracked(items, fh)
        except EyeqError as exc:
            raise _naming(exc, self.path) from None
        finally:
            self.close()

    def _expand(self, items: Iterable[Any]) -> Iterator[Any]:
        if self.config.blocks:
            yield from items
            return
        for item in items:
            if isinstance(item, dict):
                yield item
            else:
                yield from item.records()

    def _tracked(self, items: Iterator[Any], fh: IO[bytes]) -> Iterator[Any]:
        """``items``, with :attr:`progress` following how far into the file they stand: the
        read position every 32 records and at every frame block (:class:`BlockPosition`)."""
        size = _file_size(fh) if self.progress is not None else None
        if not size or self.progress is None:
            yield from items
            return
        report, where, since_report = self.progress, BlockPosition(), 0
        for item in items:
            since_report += 1
            if since_report >= 32 or not isinstance(item, dict):
                since_report = 0
                with contextlib.suppress(OSError, ValueError):
                    report(self.path, where(item, fh.tell()), size)
            yield item
        report(self.path, size, size)

    def close(self) -> None:
        fh, self._fh = self._fh, None
        if fh is not None and fh is not sys.stdin.buffer:
            fh.close()


def _naming(exc: EyeqError, path: str) -> EyeqError:
    """``exc`` with the file it is about in front (``a.pcapng: empty input``), so that with
    several files the user knows which one, and for a CAN log refused as a capture the command
    that reads it; the same class, so callers catch it as before."""
    name = "stdin" if path == "-" else path
    text = str(exc)
    hint = can_log_hint(path) if path != "-" and isinstance(exc, InputError) else None
    if hint is not None:
        text = f"{text}; {hint}"
    if not (text.startswith(f"{name}:") or text.startswith(f"{path}:")):
        text = f"{name}: {text}"
    elif hint is None:
        return exc
    try:
        named = type(exc)(text)
    except TypeError:  # an error class with other arguments: as it is
        return exc
    return named


def dissect_captures(paths: Sequence[str], config: DissectConfig | None = None, *,
                     progress: Progress | None = None) -> Iterator[CaptureFile]:
    """One :class:`CaptureFile` per path, in order; consume one's items before asking for
    the next. Raises :class:`~eyeq_spi.errors.InputError` for a file that cannot be read (when its
    turn comes; a worker's error when its file's turn comes)."""
    cfg = config or DissectConfig()
    if cfg.jobs < 0:
        raise ValueError(f"jobs must be 0 or more, not {cfg.jobs}")
    br = fast_module(paths, cfg.jobs)
    jobs = cfg.jobs or (br.default_jobs() if br is not None else 1)
    par = None
    if br is not None and jobs > 1 and len(paths) > 1 and "-" not in paths:
        par = br.parallel_items(list(paths), jobs, cfg.fmt, cfg.direction, cfg.sw, cfg.fields)
    current: CaptureFile | None = None
    with garbage.paused() if cfg.pace_gc else contextlib.nullcontext():
        try:
            for number, path in enumerate(paths, 1):
                done = next(par)[1] if par is not None else None
                current = CaptureFile(path, cfg, br, progress, done)
                yield current
                current.close()
                if par is not None and progress is not None:
                    progress(None, number, len(paths))
        finally:
            if current is not None:
                current.close()
            if par is not None:
                par.close()


class Dissection:
    """The records of :func:`dissect_files`; :attr:`files` holds the files begun so far (their
    releases, and once read, their tails)."""

    def __init__(self, paths: list[str], config: DissectConfig | None,
                 progress: Progress | None) -> None:
        self.paths, self.config, self.progress = paths, config, progress
        self.files: list[CaptureFile] = []

    def __iter__(self) -> Iterator[dict[str, Any]]:
        cfg = self.config or DissectConfig()
        if cfg.blocks:
            raise ValueError("dissect_files hands out records: use dissect_captures for blocks")
        for cf in dissect_captures(self.paths, cfg, progress=self.progress):
            self.files.append(cf)
            for record in cf.items:
                record["file"] = cf.path
                yield record

    @property
    def ignored(self) -> int:
        """Bytes the readers left at the end of the files read (pcapng cut inside a block)."""
        return sum(cf.tail.ignored for cf in self.files)


def dissect_files(paths: Sequence[str], config: DissectConfig | None = None, *,
                  progress: Progress | None = None) -> Dissection:
    """The dissector's records of the files ``paths`` in order (docs/dissector.md JSON
    contract), each with its ``file`` member: ``for record in dissect_files(["a.pcapng"])``."""
    return Dissection(list(paths), config, progress)


def open_capture_file(path: str, config: DissectConfig | None = None) -> CaptureFile:
    """One capture opened with its release (:attr:`CaptureFile.release` raises a bad input's
    :class:`~eyeq_spi.errors.InputError` now); read its :attr:`~CaptureFile.transfers` or
    :attr:`~CaptureFile.items`, then :meth:`~CaptureFile.close` it."""
    cf = CaptureFile(path, config or DissectConfig(), AUTO)
    cf.open()
    return cf


def fields_mode(writers: list[Any], plain: bool) -> str:
    """What the fast path's messages must carry for these writers
    (:class:`.engine_fast_messages.SpanDecoder`): no fields for statistics alone, columns for
    one table writer and no filter, else the fields."""
    if not writers:
        return "none"
    if (plain and len(writers) == 1 and type(writers[0]).__name__ == "TableWriter"
            and not getattr(writers[0], "errors", False)):
        return "columns"
    return "dict"


def fast_module(paths: Sequence[str], jobs: int = 1) -> Any:
    """:mod:`eyeq_spi.dissect.pipeline_fast`, or None when no input is big enough for the fast
    path (nor several files for ``jobs``): start-up of small runs stays under 300 ms."""
    if references_only():  # EYEQ_SPI_EXACT=1: the references read everything
        return None
    several = jobs != 1 and len(paths) > 1 and "-" not in paths
    big = False
    for path in paths:
        if path != "-":
            try:
                big = big or os.path.getsize(path) >= SMALL_INPUT
            except OSError:
                big = True  # let the readers report it
    if not (big or several):
        return None
    from eyeq_spi.dissect import pipeline_fast

    return pipeline_fast


class BlockPosition:
    """Where in the file a frame block of the fast path stands: its chunk was read between
    the positions seen at this chunk's first block and the previous chunk's, and the block
    ends ``hi`` rows into it (the reader reads a whole chunk before the first block)."""

    def __init__(self) -> None:
        self.fa: object = None
        self.start = self.end = 0

    def __call__(self, item: Any, pos: int) -> float:
        fa: Any = getattr(item, "fa", None)
        if fa is None or not hasattr(item, "hi"):
            return pos
        if fa is not self.fa:
            self.fa, self.start, self.end = fa, self.end, pos
        rows = max(1, len(fa.ftype))
        return float(self.start + (self.end - self.start) * min(1.0, item.hi / rows))


def paced_gc(items: Iterable[Any]) -> Iterator[Any]:
    """``items``, with the young generations of the cyclic garbage collector collected (once
    grown by ``YOUNG`` containers) after each frame block and every ``PACE`` other items, while
    the automatic collector is off (:mod:`eyeq_spi.garbage`): records are freed by reference
    counting, and the automatic collection re-scanned records under construction (0.6 of 2.1
    CPU-s of ``dissect --json``); any cycle is still freed within a block."""
    since_pace = 0
    for item in items:
        block = not isinstance(item, dict)
        yield item
        del item  # the caller drops its own reference before it asks for the next one
        since_pace += 1
        if since_pace >= PACE or block:
            since_pace = 0
            garbage.collect(YOUNG)


def _file_size(fh: IO[bytes]) -> int | None:
    """Size of a regular file behind ``fh``; None for a pipe or stdin."""
    import stat

    try:
        st = os.fstat(fh.fileno())
    except (OSError, ValueError, AttributeError):
        return None
    return st.st_size if stat.S_ISREG(st.st_mode) else None


def deliver(items: Iterable[Any], stats: Any, writers: list[Any], *,
            keep: Callable[[dict[str, Any]], bool] | None = None, path: str | None = None
            ) -> None:
    """A capture's items (:attr:`CaptureFile.items`, frame blocks whole) to its
    :class:`~.stats.Stats` and the writers: the records ``keep`` keeps (None: every record),
    each with its ``file`` member ``path``."""
    for item in items:
        if not isinstance(item, dict):  # a frame block of the fast path
            from eyeq_spi.dissect.pipeline_fast import consume

            consume(item, keep or _every, keep is None, stats, writers, path)
        else:
            if path is not None:
                item["file"] = path
            if keep is None or keep(item):  # --stats describes exactly what is kept
                stats.add(item)
                for writer in writers:
                    writer.write(item)
        item = None  # paced_gc: the block is garbage now


def _every(record: dict[str, Any]) -> bool:
    return True


