"""``eyeq-spi dissect`` and ``eyeq-spi wireshark``."""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import re
import sys
from collections.abc import Callable, Iterator
from typing import IO, Any

from eyeq_spi.errors import UsageError


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import args as ca
    from eyeq_spi.cli import options as opt

    d = sub.add_parser(name, help=help,
                       description="Decode SPI transfers: frames, reassembled messages with "
                       "their fields, link events. Exit 0 clean, 1 protocol errors found, "
                       "2 bad input or usage.",
                       parents=[opt.capture_input(
                           sw_help="SW release of the traffic (default: the one each capture "
                           "records or shows, else the newest)", spi=False),
                           opt.json_out("JSON Lines, one object per line")])
    d.add_argument("files", nargs="+", metavar="FILE", type=ca.input_file,
                   help="capture files, or - for stdin")
    d.add_argument("--csv", metavar="DIR", type=ca.output_dir,
                   help="one CSV table per message type")
    d.add_argument("--parquet", metavar="DIR", type=ca.output_dir,
                   help="one Parquet table per message type (needs the [parquet] extra)")
    d.add_argument("--stats", action="store_true",
                   help="print only summary statistics of the records the filters keep "
                   "(one JSON object with --json)")
    d.add_argument("--protocol", type=str.upper, choices=("MESP", "DASP", "DIAG", "BOOT",
                   "UNKNOWN"), help="only messages of this protocol (any case)")
    d.add_argument("--id", type=ca.message_id, metavar="ID",
                   help="only messages with this data ID, 0..255 (0xE4; 0x41 and 0x10 work "
                   "too) or message name")
    d.add_argument("--name", metavar="REGEX", type=ca.regex,
                   help="only messages whose name matches")
    d.add_argument("--errors-only", action="store_true",
                   help="only bad frames, link events and messages with errors")
    d.add_argument("--no-tree", action="store_true", help="no field tree in the human view")
    d.add_argument("--jobs", "-j", type=opt.limited("dissect_jobs"), default=1, metavar="N",
                   help="dissect N files at a time in worker processes (same output as one "
                   "at a time; 0: one per CPU)")
    opt.add_spi_arguments(d)


def run(args: argparse.Namespace) -> int:
    return run_dissect(args)


def _filter(args: argparse.Namespace) -> Callable[[dict[str, Any]], bool]:
    try:
        name_re = re.compile(args.name) if args.name else None
    except re.error as exc:
        raise UsageError(f"--name: bad regular expression: {exc}") from None
    message_filter = bool(args.protocol or args.id is not None or name_re)

    def keep(r: dict[str, Any]) -> bool:
        kind = r["kind"]
        if kind == "frame":
            if args.errors_only:
                return bool(not r["crc_ok"] or r["frame_type"] in ("NAK", "INVALID"))
            return not message_filter
        if kind == "event":
            return not message_filter or args.errors_only
        if args.protocol and r["protocol"] != args.protocol:
            return False
        if args.id is not None:
            ident = r["header"].get("data_id", r["header"].get("id"))
            if ident != args.id:
                return False
        if name_re and not name_re.search(r["name"] or ""):
            return False
        return not args.errors_only or bool(r["errors"])

    return keep


def run_dissect(args: argparse.Namespace) -> int:
    from eyeq_spi.dissect.output import HumanWriter, JsonWriter, TableWriter
    from eyeq_spi.dissect.stats import Stats, combine
    from eyeq_spi.spec.catalog import catalog

    if args.csv and args.parquet:
        raise UsageError("give --csv or --parquet, not both")
    if args.files.count("-") > 1:
        raise UsageError("stdin (-) can be given once")
    cat = catalog()
    keep = _filter(args)
    writers: list[Any] = []
    table = None
    if args.csv or args.parquet:
        table = TableWriter(args.csv or args.parquet, "csv" if args.csv else "parquet")
        writers.append(table)
    out = sys.stdout
    human = None
    if args.stats:
        pass  # statistics only (as text, or one JSON object per file with --json)
    elif args.json:
        writers.append(JsonWriter(out, fast=True))
    elif not table:
        human = HumanWriter(out, _codec(cat.default_sw), color=out.isatty(),
                            tree=not args.no_tree)
        writers.append(human)
        if not _plain(args):  # the filters drop records: the human view still dates from
            kept = keep  # the file's first record, as plot does

            def keep(r: dict[str, Any]) -> bool:
                human.see(r)
                return kept(r)
    per_file: list[Stats] = []
    gc_was = gc.isenabled()
    gc.disable()  # collected by _paced_gc instead
    bars = contextlib.ExitStack()
    try:
        br: Any = _batch_run(args)  # None for small inputs: numpy costs more than it saves
        plain = _plain(args)
        if args.jobs < 0:
            raise UsageError(f"--jobs must be 0 or more, not {args.jobs}")
        jobs = args.jobs or (br.default_jobs() if br is not None else 1)
        par = None
        if br is not None and jobs > 1 and len(args.files) > 1 and "-" not in args.files:
            par = br.parallel_items(args.files, jobs, args.format, args.direction, args.sw,
                                    br.fields_mode(writers, plain))
        from eyeq_spi.cli.progress import JobProgress

        # --jobs: files are decoded in workers, so the bar counts files as they arrive (a
        # file read here has its own bar over its bytes instead)
        files_bar = bars.enter_context(JobProgress(
            f"dissect {len(args.files)} files", len(args.files), unit="files",
            records_on_stdout=bool(writers) and table is None,
            enabled=None if par is not None else False))
        for n, path in enumerate(args.files, 1):
            done = next(par)[1] if par is not None else None
            stats = Stats(cat, file=path)
            per_file.append(stats)
            if table is not None:
                table.file = path
            if human is not None and len(args.files) > 1:
                out.write(f"=== {path}\n")
            if done is not None:
                items, release, tail = done
                _file_start(path, release, stats, human)
                _feed(_paced_gc(items), br, keep, plain, stats, writers, path)
            else:
                tail = _dissect_file(path, args, br, plain, keep, stats, writers, human)
            if tail.ignored:
                stats.ignored_bytes = tail.ignored
                print(f"eyeq-spi dissect: {tail.note(path)}", file=sys.stderr, flush=True)
            stats.finish()
            files_bar.update(n)
    finally:
        bars.close()
        if gc_was:
            gc.enable()
        if table is not None:
            table.close()
    if args.stats:
        shown = [*per_file, combine(per_file)] if len(per_file) > 1 else per_file
        for st in shown:
            if args.json:
                JsonWriter(out, fast=True).write(st.as_dict())
            else:
                out.write(st.render() + "\n")
    return 1 if any(st.protocol_errors or st.ignored_bytes for st in per_file) else 0


_CODECS: dict[str, Any] = {}


def _codec(key: str) -> Any:
    from eyeq_spi.codec.message import MessageCodec

    if key not in _CODECS:
        _CODECS[key] = MessageCodec(key)
    return _CODECS[key]


def _file_start(path: str, release: Any, stats: Any, human: Any) -> None:
    """The release a file is read with: in its statistics, to the human view, and the one-line
    warning when ``--sw`` disagrees with the capture."""
    stats.sw = release.as_dict()
    if human is not None:
        human.codec = _codec(release.key)
    if release.warning:
        print(f"eyeq-spi dissect: warning: {release.warning}", file=sys.stderr, flush=True)


def _feed(items: Any, br: Any, keep: Callable[[dict[str, Any]], bool], plain: bool,
          stats: Any, writers: list[Any], path: str) -> None:
    for r in items:
        if br is not None and isinstance(r, br.FrameBlock):  # the batch path
            br.consume(r, keep, plain, stats, writers, path)
        else:
            r["file"] = path
            if keep(r):  # --stats describes exactly what the filters keep
                stats.add(r)
                for w in writers:
                    w.write(r)
        r = None  # _paced_gc: the block is garbage now


def _dissect_file(path: str, args: argparse.Namespace, br: Any, plain: bool,
                  keep: Callable[[dict[str, Any]], bool], stats: Any, writers: list[Any],
                  human: Any) -> Any:
    """One file in this process (the batch path when it is a seekable pcapng or raw file, else
    the exact engine); returns what its reader left at its end."""
    from eyeq_spi.cli.options import spi_options
    from eyeq_spi.dissect.engine import Dissector
    from eyeq_spi.dissect.release import open_capture

    fh = _open(path)
    try:
        cap = open_capture(fh, args.format, args.direction, spi_options(args), sw=args.sw,
                           name=path)
        _file_start(path, cap.release, stats, human)
        codec = _codec(cap.release.key)
        batched = (br.batch_items(fh, args.format, args.direction, codec,
                                  fields=br.fields_mode(writers, plain), tail=cap.tail)
                   if br is not None else None)
        table = any(type(w).__name__ == "TableWriter" for w in writers)
        items = _with_progress(batched or _all(Dissector(codec=codec), cap.records), fh, path,
                               stdout_busy=bool(writers) and not table)
        _feed(_paced_gc(items), br, keep, plain, stats, writers, path)
        return cap.tail
    finally:
        if fh is not sys.stdin.buffer:
            fh.close()



def _with_progress(it: Iterator[Any], fh: IO[bytes], path: str,
                   stdout_busy: bool = False) -> Iterator[Any]:
    """The shared progress bar (:mod:`eyeq_spi.cli.progress`) over one file: on stderr, only
    where it cannot land between records, following the batch path's blocks inside a chunk."""
    from eyeq_spi.cli.progress import JobProgress, file_size, track_file

    size = file_size(fh)
    bar = JobProgress(f"dissect {os.path.basename(path)}", size,
                      records_on_stdout=stdout_busy, enabled=None if size else False)
    with bar:
        yield from track_file(it, fh, bar, _BlockPosition())

class _BlockPosition:
    """Where in the file a frame block of the batch path stands: its chunk was read between
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


def _plain(args: argparse.Namespace) -> bool:
    """No filter: every record is kept."""
    return not (args.protocol or args.id is not None or args.name or args.errors_only)


SMALL_INPUT = 256 << 10  # bytes; below this the exact path is quicker than importing numpy


def _batch_run(args: argparse.Namespace) -> Any:
    """``eyeq_spi.dissect.batch_run``, or None when no input is big enough for the batch path
    (nor several files for ``--jobs``): start-up of small runs stays under 300 ms."""
    several = args.jobs != 1 and len(args.files) > 1 and "-" not in args.files
    big = False
    for path in args.files:
        if path != "-":
            try:
                big = big or os.path.getsize(path) >= SMALL_INPUT
            except OSError:
                big = True  # let the readers report it
    if not (big or several):
        return None
    from eyeq_spi.dissect import batch_run

    return batch_run


PACE = 4096  # records between two looks at the young generation
YOUNG = 20_000  # containers it must have grown by to be collected


def _paced_gc(items: Any) -> Iterator[Any]:
    """``items``, with the young generations of the cyclic garbage collector collected (when
    they have grown by ``YOUNG`` containers) after each frame block and every ``PACE`` other
    items, while the automatic collector is off.

    Records are trees of dicts and lists freed by reference counting; the default automatic
    collection (every 700 new containers) re-scanned records under construction (1,500
    containers in one obstacles message) and spent 0.6 of 2.1 CPU-s of ``dissect --json`` on a
    90 s capture. Here a collection sees only what is alive between two blocks, and any cycle is
    still freed within a block, so memory stays bounded."""
    n = 0
    for item in items:
        block = not isinstance(item, dict)
        yield item
        del item  # the caller drops its own reference before it asks for the next one
        n += 1
        if n >= PACE or block:
            n = 0
            if gc.get_count()[0] >= YOUNG:
                gc.collect(1)


def _all(dis: Any, records: Iterator[Any]) -> Iterator[dict[str, Any]]:
    for rec in records:
        yield from dis.feed(rec)
    yield from dis.finish()


def _open(path: str) -> IO[bytes]:
    from eyeq_spi.dissect.inputs import InputError

    if path == "-":
        return sys.stdin.buffer
    try:
        return open(path, "rb")
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror or exc}") from None
