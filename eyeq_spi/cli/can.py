"""``eyeq-spi can dbc`` and ``eyeq-spi can decode``: the Mobileye CAN output protocols of
``specs/can/`` (seeds 000, 001, 003) as generated DBC files, and a CAN log decoder whose outputs
follow ``eyeq-spi dissect`` (human, ``--json`` lines, ``--csv``/``--parquet`` tables, ``--stats``).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from eyeq_spi.errors import InputError, TruncatedInputError, UsageError

PROTOCOLS = ("extlog2", "me8")


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import options as opt

    c = sub.add_parser(name, help=help,
                       description="The Mobileye CAN protocols of specs/can/: ExtLogData2/AWS/"
                       "LKA (extlog2, seeds 000/001) and Mobileye 8 Connect (me8, seed 003).")
    cs = c.add_subparsers(dest="can_command", required=True, parser_class=sub._parser_class)
    d = cs.add_parser("dbc", help="write DBC files built with cantools from specs/can/")
    d.add_argument("--protocol", choices=(*PROTOCOLS, "all"), default="all",
                   help="which protocol (default all)")
    d.add_argument("--output", "-o", metavar="DIR", default=".",
                   help="directory for PROTOCOL.dbc (default .); - prints one protocol")
    k = cs.add_parser("compare", help="compare a vendor's DBC with ours, signal by signal",
                      description="A DBC you hold (vendor, public) against the DBC built from "
                      "specs/can/: ID, DLC, cycle and each signal's start, length, byte order, "
                      "sign, scale, offset, range, invalid value, with our reason (seed line, "
                      "decision) where they differ. Exit 0 the same, 1 differences, 2 bad "
                      "input.")
    k.add_argument("dbc", metavar="OTHER.dbc", help="the DBC file to compare")
    k.add_argument("--protocol", choices=PROTOCOLS, default="extlog2",
                   help="our protocol to compare with (default extlog2)")
    opt.include(k, opt.json_out("the differences as a JSON list"))
    x = cs.add_parser("decode", help="decode BLF, ASC, candump .log, TRC or MF4 CAN logs, "
                      "or a live bus",
                      description="Decode CAN logs with the protocols of specs/can/. Exit 0 "
                      "clean, 1 frames with errors (unknown ID, wrong DLC, value out of range) "
                      "or a truncated log, 2 bad input or usage. Cycle-time deviations and "
                      "short DLCs that hold every signal are shown, not errors.")
    x.add_argument("logs", nargs="*", metavar="LOG", help="CAN log files (.blf .asc .log .trc "
                   ".mf4 .csv)")
    x.add_argument("--protocol", choices=PROTOCOLS, default="extlog2",
                   help="protocol of the log (default extlog2)")
    opt.include(x, opt.json_out("JSON Lines, one object per frame"))
    x.add_argument("--csv", metavar="DIR", help="one CSV table per message")
    x.add_argument("--parquet", metavar="DIR", help="one Parquet table per message")
    x.add_argument("--stats", action="store_true",
                   help="only statistics: frames per channel, per ID the cycle time against "
                   "the spec, DLC errors, short DLCs, invalid and out-of-range values per "
                   "signal (one JSON object with --json)")
    x.add_argument("--bus", metavar="INTERFACE:CHANNEL",
                   help="decode a live python-can bus instead of logs (virtual:NAME, "
                   "socketcan:can0, ...) until --count, --duration or Ctrl-C")
    x.add_argument("--count", type=int, metavar="N", help="--bus: stop after N frames")
    x.add_argument("--duration", type=float, metavar="S", help="--bus: stop after S seconds")
    x.add_argument("--channel", metavar="N",
                   help="only frames of this channel (python-can Message.channel, as --stats "
                   "lists them)")
    x.add_argument("--raw-invalid", action="store_true",
                   help="--csv/--parquet: write the decoded number of a value at its invalid "
                   "value (default: empty / NULL)")
    x.add_argument("--id", metavar="ID", type=lambda s: int(s, 0),
                   help="only frames with this arbitration ID (0x739)")
    x.add_argument("--name", metavar="REGEX", help="only messages whose name matches")
    x.add_argument("--errors-only", action="store_true",
                   help="only frames with errors (not with --stats, which counts them)")


def _compare(args: argparse.Namespace) -> int:
    from eyeq_spi.can.compare import as_json, compare, human

    diffs = compare(args.dbc, args.protocol)
    if args.json:
        import json

        print(json.dumps(as_json(diffs), indent=1))
    else:
        print(human(diffs, args.dbc, args.protocol))
    return 1 if diffs else 0


def _dbc(args: argparse.Namespace) -> int:
    from eyeq_spi.can.dbc import dbc_text, write_dbc

    names = PROTOCOLS if args.protocol == "all" else (args.protocol,)
    if args.output == "-":
        if len(names) != 1:
            raise UsageError("--output - prints one protocol: add --protocol extlog2 or me8")
        sys.stdout.write(dbc_text(names[0]))
        return 0
    for n in names:
        path = write_dbc(n, Path(args.output))
        print(path)
    return 0


def _sources(args: argparse.Namespace) -> Any:
    """One iterator of python-can messages per log file, or the live bus (shut down after)."""
    from eyeq_spi.can.logs import open_bus, read_bus, read_log

    if not args.bus:
        for path in args.logs:
            yield read_log(path)
        return
    bus = open_bus(args.bus)
    try:
        yield read_bus(bus, duration=args.duration, count=args.count)
    finally:
        bus.shutdown()


class _JsonLines:
    """JSON Lines with orjson, written in blocks (``dissect --json``'s fast spelling)."""

    def __init__(self) -> None:
        import orjson

        self._dumps = orjson.dumps
        self._opt = orjson.OPT_APPEND_NEWLINE
        self._out = getattr(sys.stdout, "buffer", None)
        self._block: list[bytes] = []
        dumps, opt, block = self._dumps, self._opt, self._block
        add = block.append

        def write(rec: dict[str, Any]) -> None:  # the hot path: locals only
            add(dumps(rec, option=opt))
            if len(block) >= 512:
                self.flush()

        self.write: Callable[[dict[str, Any]], None] = write

    def flush(self) -> None:
        data = b"".join(self._block)
        self._block.clear()
        if self._out is not None:
            sys.stdout.flush()
            self._out.write(data)
        else:  # a text stream without a buffer (tests capture into StringIO)
            sys.stdout.write(data.decode())


def _decode(args: argparse.Namespace) -> int:
    from eyeq_spi.can.decode import CanDecoder, human_record, table_record
    from eyeq_spi.can.stats import CanStats, human_stats
    from eyeq_spi.dissect.output import JsonWriter, TableWriter

    if args.csv and args.parquet:
        raise UsageError("give --csv or --parquet, not both")
    try:
        name_re = re.compile(args.name) if args.name else None
    except re.error as exc:
        raise UsageError(f"--name: bad regular expression: {exc}") from None
    if bool(args.bus) == bool(args.logs):
        raise UsageError("give CAN log files or --bus INTERFACE:CHANNEL (one of them)")
    if not args.bus and (args.count is not None or args.duration is not None):
        raise UsageError("--count and --duration apply to --bus")
    decoder = CanDecoder(args.protocol)
    channel = args.channel
    truncated: list[str] = []
    if args.stats:
        stats = CanStats(decoder, channel)
        for source in _sources(args):
            try:
                stats.add_all(source)
            except TruncatedInputError as exc:
                truncated.append(str(exc))
            except KeyboardInterrupt:  # a live bus: stop and report what was received
                pass
        result = stats.result()
        bad = stats.error_frames
        if args.id is not None or name_re is not None:  # only the IDs asked for
            result["ids"] = [r for r in result["ids"]
                             if (args.id is None or r["id"] == args.id)
                             and (name_re is None or name_re.search(r["name"] or ""))]
            bad = sum(r["error_frames"] for r in result["ids"])
        if stats.frames == 0 and not truncated:
            raise InputError("no CAN frames in the input" if channel is None else
                             f"no CAN frames on channel {channel} (the channels are: "
                             f"{', '.join(result['channels']) or 'none'})")
        if args.json:
            JsonWriter(sys.stdout, fast=True).write(result)
        else:
            print(human_stats(result))
        for line in truncated:
            print(f"eyeq-spi can decode: {line}", file=sys.stderr)
        return 1 if bad or truncated else 0

    table = None
    if args.csv or args.parquet:
        table = TableWriter(args.csv or args.parquet, "csv" if args.csv else "parquet",
                            column_type=decoder.column_type)
    json_out = _JsonLines() if args.json else None
    bad = 0
    index = 0
    kept = 0
    emit: Any
    if table is not None:
        raw_invalid = args.raw_invalid
        tw = table.write

        def emit(rec: dict[str, Any]) -> None:
            tw(table_record(rec, raw_invalid))
    elif json_out is not None:
        emit = json_out.write
    else:
        def emit(rec: dict[str, Any]) -> None:
            print(human_record(rec))
    want_id = args.id
    errors_only = args.errors_only
    others: set[str] = set()  # channels skipped by --channel, named if none matched
    decode = decoder.decode
    try:
        for source in _sources(args):
            try:
                for msg in source:
                    index += 1
                    if channel is not None and str(msg.channel) != channel:
                        others.add(str(msg.channel))
                        continue
                    if want_id is not None and msg.arbitration_id != want_id:
                        continue
                    rec = decode(msg, index - 1)
                    kept += 1
                    if name_re is not None and not name_re.search(rec["name"] or ""):
                        continue
                    if rec["errors"]:
                        bad += 1
                    elif errors_only:
                        continue
                    emit(rec)
            except TruncatedInputError as exc:
                truncated.append(str(exc))
            except KeyboardInterrupt:  # a live bus: stop, keep what was decoded
                pass
    finally:
        if table is not None:
            table.close()
        if json_out is not None:
            json_out.flush()
    if index == 0 and not truncated:
        raise InputError("no CAN frames in the input")
    if kept == 0 and channel is not None and not truncated:
        raise InputError(f"no CAN frames on channel {channel} (the channels are: "
                         f"{', '.join(sorted(others)) or 'none'})")
    for line in truncated:
        print(f"eyeq-spi can decode: {line}", file=sys.stderr)
    return 1 if bad or truncated else 0


def run(args: argparse.Namespace) -> int:
    if args.can_command == "compare":
        return _compare(args)
    return _dbc(args) if args.can_command == "dbc" else _decode(args)
