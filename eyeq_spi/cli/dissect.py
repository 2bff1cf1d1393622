"""``eyeq-spi dissect`` and ``eyeq-spi wireshark``."""

from __future__ import annotations

import argparse
import os
import re
import sys
from collections.abc import Callable
from typing import Any

from eyeq_spi.errors import UsageError


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import args as ca
    from eyeq_spi.cli import options as opt

    parser = sub.add_parser(name, help=help,
                       description="Decode SPI transfers: frames, reassembled messages with "
                       "their fields, link events. Exit 0 clean, 1 protocol errors found, "
                       "2 bad input or usage.",
                       parents=[opt.capture_input(
                           direction_help="channel of a raw or hex file without directions",
                           sw_help="SW release of the traffic (default: the one each capture "
                           "records or shows, else the newest)", spi=False),
                           opt.json_out("JSON Lines, one object per line")])
    parser.add_argument("files", nargs="+", metavar="FILE", type=ca.input_file,
                   help="capture files, or - for stdin")
    parser.add_argument("--csv", metavar="DIR", type=ca.output_dir,
                   help="one CSV table per message type")
    parser.add_argument("--parquet", metavar="DIR", type=ca.output_dir,
                   help="one Parquet table per message type (needs the [parquet] extra)")
    parser.add_argument("--stats", action="store_true",
                   help="print only summary statistics of the records the filters keep "
                   "(one JSON object with --json)")
    parser.add_argument("--protocol", type=str.upper, choices=("MESP", "DASP", "DIAG", "BOOT",
                   "UNKNOWN"), help="only messages of this protocol (any case)")
    parser.add_argument("--id", type=ca.message_id, metavar="ID",
                   help="only messages with this data ID, 0..255 (0xE4; 0x41 and 0x10 work "
                   "too) or message name")
    parser.add_argument("--name", metavar="REGEX", type=ca.regex,
                   help="only messages whose name matches")
    parser.add_argument("--errors-only", action="store_true",
                   help="only bad frames, link events and messages with errors")
    parser.add_argument("--no-tree", action="store_true", help="no field tree in the human view")
    parser.add_argument("--jobs", "-j", type=opt.limited("dissect_jobs"), default=1, metavar="N",
                   help="dissect N files at a time in worker processes (same output as one "
                   "at a time; 0: one per CPU)")
    opt.add_spi_arguments(parser)


def _filter(args: argparse.Namespace) -> Callable[[dict[str, Any]], bool] | None:
    """What the filters keep; None when they keep every record."""
    name_re = re.compile(args.name) if args.name else None
    message_filter = bool(args.protocol or args.id is not None or name_re)
    if not (message_filter or args.errors_only):
        return None

    def keep(record: dict[str, Any]) -> bool:
        kind = record["kind"]
        if kind == "frame":
            if args.errors_only:
                return bool(not record["crc_ok"] or record["frame_type"] in ("NAK", "INVALID"))
            return not message_filter
        if kind == "event":
            return not message_filter or args.errors_only
        if args.protocol and record["protocol"] != args.protocol:
            return False
        if args.id is not None:
            ident = record["header"].get("data_id", record["header"].get("id"))
            if ident != args.id:
                return False
        if name_re and not name_re.search(record["name"] or ""):
            return False
        return not args.errors_only or bool(record["errors"])

    return keep


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.catalog.messages import catalog
    from eyeq_spi.cli.options import spi_options
    from eyeq_spi.dissect.output import HumanWriter, TableWriter
    from eyeq_spi.dissect.pipeline import DissectConfig, deliver, dissect_captures, fields_mode
    from eyeq_spi.dissect.release import codec_for
    from eyeq_spi.dissect.stats import Stats
    from eyeq_spi.io.jsonl import JsonLinesWriter

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
        writers.append(JsonLinesWriter(out, fast=True))
    elif not table:
        human = HumanWriter(out, codec_for(cat.default_sw), color=out.isatty(),
                            tree=not args.no_tree)
        writers.append(human)
        if keep is not None:  # the filters drop records: the human view still dates from
            kept = keep  # the file's first transfer, as plot does

            def keep(record: dict[str, Any]) -> bool:
                human.see(record)
                return kept(record)
    config = DissectConfig(fmt=args.format, direction=args.direction,
                           spi=spi_options(args), sw=args.sw, jobs=args.jobs,
                           fields=fields_mode(writers, keep is None), blocks=True)
    per_file: list[Stats] = []
    bars = _Bars(len(args.files), records_on_stdout=bool(writers) and table is None)
    try:
        for cf in dissect_captures(args.files, config, progress=bars):
            path = cf.path
            stats = Stats(cat, file=path)
            per_file.append(stats)
            if table is not None:
                table.file = path
            if human is not None and len(args.files) > 1:
                out.write(f"=== {path}\n")
            release = cf.release
            stats.sw = release.as_dict()
            if human is not None:
                human.codec = codec_for(release.key)
            if release.warning:
                print(f"eyeq-spi dissect: warning: {release.warning}", file=sys.stderr,
                      flush=True)
            deliver(cf.items, stats, writers, keep=keep, path=path)
            if cf.tail.ignored:
                stats.ignored_bytes = cf.tail.ignored
                print(f"eyeq-spi dissect: {cf.tail.note(path)}", file=sys.stderr, flush=True)
            stats.finish()
    finally:
        bars.close()
        if table is not None:
            table.close()
    if args.stats:
        _print_stats(per_file, out, as_json=args.json)
    return 1 if any(st.protocol_errors or st.ignored_bytes for st in per_file) else 0


def _print_stats(per_file: list[Any], out: Any, *, as_json: bool) -> None:
    """Each file's statistics, then their total when there are several."""
    from eyeq_spi.dissect.stats import combine
    from eyeq_spi.io.jsonl import JsonLinesWriter

    shown = [*per_file, combine(per_file)] if len(per_file) > 1 else per_file
    for st in shown:
        if as_json:
            JsonLinesWriter(out, fast=True).write(st.as_dict())
        else:
            out.write(st.render() + "\n")


class _Bars:
    """The pipeline's progress on the shared bars (:mod:`eyeq_spi.cli.progress`), on stderr and
    only where they cannot land between records: one over the bytes of each file read here,
    or one over the files when they are decoded in worker processes (``--jobs``)."""

    def __init__(self, files: int, records_on_stdout: bool) -> None:
        self.files = files
        self.records_on_stdout = records_on_stdout
        self.bar: Any = None
        self.path: str | None = None  # what the bar is about: a file, or None (the files)
        self.finished: set[str] = set()  # files whose bar ran to its end

    def __call__(self, path: str | None, done: float, total: float | None) -> None:
        from eyeq_spi.cli.progress import JobProgress

        if path in self.finished:
            return  # later calls about a finished file redraw nothing
        if self.bar is None or path != self.path:
            self.close()
            self.path = path
            label, unit = ((f"dissect {self.files} files", "files") if path is None
                           else (f"dissect {os.path.basename(path)}", "bytes"))
            self.bar = JobProgress(label, self.files if path is None else total, unit=unit,
                                   records_on_stdout=self.records_on_stdout)
            self.bar.__enter__()
        self.bar.update(done)
        if path is not None and total is not None and done >= total:
            self.finished.add(path)
            self.close()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.__exit__(None, None, None)
        self.bar = None
