"""``eyeq-spi can dbc`` and ``eyeq-spi can decode``: the Mobileye CAN output protocols of
``specs/can/`` (seeds 000, 001, 003) as generated DBC files, and a CAN log decoder whose outputs
follow ``eyeq-spi dissect`` (human, ``--json`` lines, ``--csv``/``--parquet`` tables, ``--stats``).
"""

from __future__ import annotations

import argparse
import contextlib
import re
import sys
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from eyeq_spi.errors import InputError, TruncatedInputError, UsageError

PROTOCOLS = ("extlog2", "me8")


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import args as ca
    from eyeq_spi.cli import options as opt

    parser = sub.add_parser(name, help=help,
                       description="The Mobileye CAN protocols of specs/can/: ExtLogData2/AWS/"
                       "LKA (extlog2, seeds 000/001) and Mobileye 8 Connect (me8, seed 003).")
    cs = parser.add_subparsers(dest="can_command", required=True, parser_class=sub._parser_class)
    dbc = cs.add_parser("dbc", help="write DBC files built with cantools from specs/can/")
    dbc.add_argument("--protocol", choices=(*PROTOCOLS, "all"), default="all",
                   help="which protocol (default all)")
    dbc.add_argument("--output", "-o", metavar="DIR", default=".",
                   help="directory for PROTOCOL.dbc (default .); - prints one protocol")
    compare = cs.add_parser("compare", help="compare a vendor's DBC with ours, signal by signal",
                      description="A DBC you hold against the DBC built from specs/can/, "
                      "message by message and signal by signal; each difference says ours -> "
                      "theirs and where ours comes from. Exit 0 the same, 1 differences, 2 bad "
                      "input.")
    compare.add_argument("dbc", metavar="OTHER.dbc", help="the DBC file to compare")
    compare.add_argument("--protocol", choices=PROTOCOLS,
                   help="our protocol to compare with (default: the one whose IDs the DBC "
                   "holds most of)")
    opt.include(compare, opt.json_out("the differences as a JSON list"))
    decode = cs.add_parser("decode", help="decode BLF, ASC, candump .log, TRC or MF4 CAN logs, "
                      "or a live bus",
                      description="Decode CAN logs (each on its own) with the protocols of "
                      "specs/can/. Exit 0 clean, 1 frames with errors (wrong DLC, value out of "
                      "range) or a truncated log, 2 bad input or usage; other nodes' frames, "
                      "cycle-time deviations and invalid values are shown, not errors.")
    decode.add_argument("logs", nargs="*", metavar="LOG", help="CAN log files (.blf .asc .log .trc "
                   ".mf4 .csv)")
    decode.add_argument("--protocol", choices=PROTOCOLS, default="extlog2",
                   help="protocol of the log (default extlog2)")
    opt.include(decode, opt.json_out("JSON Lines, one object per frame"))
    decode.add_argument("--csv", metavar="DIR", help="one CSV table per message")
    decode.add_argument("--parquet", metavar="DIR", help="one Parquet table per message")
    decode.add_argument("--stats", action="store_true",
                   help="only statistics: frames per channel, per ID the cycle time against "
                   "the spec, DLC errors, short DLCs, invalid and out-of-range values per "
                   "signal (one JSON object with --json)")
    decode.add_argument("--bus", metavar="INTERFACE:CHANNEL",
                   help="decode a live python-can bus instead of logs (virtual:NAME, "
                   "socketcan:can0, ...) until --count, --duration or Ctrl-C")
    decode.add_argument("--count", type=int, metavar="N", help="--bus: stop after N frames")
    decode.add_argument("--duration", type=float, metavar="S", help="--bus: stop after S seconds")
    decode.add_argument("--channel", metavar="N",
                   help="only frames of this channel (python-can Message.channel, as --stats "
                   "lists them)")
    decode.add_argument("--raw-invalid", action="store_true",
                   help="--csv/--parquet: write the decoded number of a value at its invalid "
                   "value (default: empty / NULL)")
    decode.add_argument("--absolute-time", action="store_true",
                   help="times as the log records them (default: seconds since the log's "
                   "first frame)")
    decode.add_argument("--id", metavar="ID", type=can_id,
                   help="only frames with this arbitration ID (0x739)")
    decode.add_argument("--name", metavar="REGEX", type=ca.regex,
                        help="only messages whose name matches")
    decode.add_argument("--errors-only", action="store_true",
                   help="only frames with errors (not with --stats, which counts them)")


def _compare(args: argparse.Namespace) -> int:
    from eyeq_spi.can.compare import as_json, compare, detect, grouped, human

    proto, detected = args.protocol, ""
    if proto is None:
        proto, share = detect(args.dbc)
        if proto is None:
            raise InputError(f"{args.dbc}: none of its frame IDs is a message of "
                                  f"{' or '.join(PROTOCOLS)}: give --protocol")
        detected = share
    diffs = grouped(compare(args.dbc, proto), proto)
    if args.json:
        import json

        print(json.dumps(as_json(diffs), indent=1))
    else:
        print(human(diffs, args.dbc, proto, detected))
    return 1 if diffs else 0


def _dbc(args: argparse.Namespace) -> int:
    from eyeq_spi.can.dbc import dbc_text, write_dbc

    names = PROTOCOLS if args.protocol == "all" else (args.protocol,)
    if args.output == "-":
        if len(names) != 1:
            raise UsageError("--output - prints one protocol: add --protocol extlog2 or me8")
        sys.stdout.write(dbc_text(names[0]))
        return 0
    for name in names:
        path = write_dbc(name, Path(args.output))
        print(path)
    return 0


def can_id(text: str) -> int:
    """``--id``: an 11- or 29-bit CAN ID, hexadecimal (0x739) or decimal."""
    try:
        value = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid CAN ID {text!r} (give it as 0x739 or "
                                         "1849)") from None
    if not 0 <= value < 1 << 29:
        raise argparse.ArgumentTypeError(f"invalid CAN ID {text!r} (0 to 0x1FFFFFFF)")
    return value


def _sources(args: argparse.Namespace) -> Iterator[tuple[str, Any]]:
    """(name, python-can messages) per log file, or for the live bus (shut down after)."""
    from eyeq_spi.can.logs import open_bus, read_bus, read_log

    if not args.bus:
        for path in args.logs:
            yield path, read_log(path)
        return
    bus = open_bus(args.bus)
    try:
        yield args.bus, read_bus(bus, duration=args.duration, count=args.count)
    finally:
        bus.shutdown()


def _decode_args(args: argparse.Namespace) -> re.Pattern[str] | None:
    """Usage checks of ``can decode``; the compiled ``--name``."""
    if args.csv and args.parquet:
        raise UsageError("give --csv or --parquet, not both")
    name_re = re.compile(args.name) if args.name else None
    if bool(args.bus) == bool(args.logs):
        raise UsageError("give CAN log files or --bus INTERFACE:CHANNEL (one of them)")
    if not args.bus and (args.count is not None or args.duration is not None):
        raise UsageError("--count and --duration apply to --bus")
    return name_re


def _warn(text: str) -> None:
    """A note on stderr, folded to 80 columns (an error stays one line: the CLI's)."""
    import textwrap

    print("\n".join(textwrap.wrap(f"eyeq-spi can decode: {text}", 80,
                                   subsequent_indent="    ", break_on_hyphens=False)),
          file=sys.stderr)


def _decode_stats(args: argparse.Namespace, decoder: Any,
                  name_re: re.Pattern[str] | None) -> int:
    """``--stats``: one block per file (cycles never span two files), then a total."""
    from eyeq_spi.can.stats import CanStats, human_stats, human_total, total

    results, truncated = [], []
    several = len(args.logs) > 1
    for label, source in _sources(args):
        stats = CanStats(decoder, args.channel, label)
        try:
            stats.add_all(source)
        except TruncatedInputError as exc:
            truncated.append(str(exc))
        except KeyboardInterrupt:  # a live bus: stop and report what was received
            pass
        result = stats.result()
        if args.id is not None or name_re is not None:  # only the IDs asked for
            result["ids"] = [r for r in result["ids"]
                             if (args.id is None or r["id"] == args.id)
                             and (name_re is None or name_re.search(r["name"] or ""))]
            result["error_frames"] = sum(r["error_frames"] for r in result["ids"])
        results.append(result)
    if sum(r["frames"] for r in results) == 0 and not truncated:
        channels = sorted({c for r in results for c in r["channels"]})
        raise InputError("no CAN frames in the input" if args.channel is None else
                          f"no CAN frames on channel {args.channel} (the channels are: "
                          f"{', '.join(channels) or 'none'})")
    blocks = [*results, total(results)] if several else results
    for block in blocks:
        if args.json:
            from eyeq_spi.io.jsonl import JsonLinesWriter

            JsonLinesWriter(sys.stdout, fast=True).write(block)
        elif "files" in block:
            print(human_total(block))
        else:
            print(human_stats(block, heading=several))
    for result in results:
        if result.get("warning"):
            _warn(f"{result['file']}: warning: {result['warning']}")
    for line in truncated:  # one line each, as an error is
        print(f"eyeq-spi can decode: {line}", file=sys.stderr)
    return 1 if any(r["error_frames"] for r in results) or truncated else 0


@dataclass
class _Run:
    """What a records run has seen, over every file."""

    frames: int = 0
    kept: int = 0
    bad: int = 0
    other: Counter[int] = field(default_factory=Counter)
    skipped_channels: set[str] = field(default_factory=set)
    truncated: list[str] = field(default_factory=list)


def _record_sink(args: argparse.Namespace, decoder: Any) -> tuple[Any, Callable[[], None]]:
    """(emit one record, close) for the human view, ``--json`` or the tables."""
    from eyeq_spi.can.decode import human_record, table_record

    if args.csv or args.parquet:
        from eyeq_spi.dissect.output import TableWriter

        table = TableWriter(args.csv or args.parquet, "csv" if args.csv else "parquet",
                            column_type=decoder.column_type)

        def emit(rec: dict[str, Any]) -> None:
            table.write(table_record(rec, args.raw_invalid))
        return emit, table.close
    if args.json:
        from eyeq_spi.io.jsonl import JsonLinesWriter

        return JsonLinesWriter(sys.stdout, fast=True).write, sys.stdout.flush

    def show(rec: dict[str, Any]) -> None:
        print(human_record(rec))
    return show, lambda: None


def _camera(args: argparse.Namespace, label: str) -> str | None:
    """The camera's channel of a log whose protocol IDs are on several channels (C10), from its
    first frames; warns when a chosen channel does not look like a camera."""
    from eyeq_spi.can.channels import ChannelCensus
    from eyeq_spi.can.decode import CanDecoder
    from eyeq_spi.can.logs import read_log

    if args.bus:
        return None
    census = ChannelCensus(CanDecoder(args.protocol))
    with contextlib.suppress(InputError):  # the decoding pass reports it
        census.add_messages(read_log(label))
    if args.channel is not None:
        verdict = census.verdict(args.channel)
        if census.frames.get(args.channel) and not verdict.looks_like_camera:
            _warn(f"{label}: warning: channel {args.channel} does not look like a camera: "
                  f"{verdict.describe()} of {args.protocol}")
        return None
    best = census.camera()
    if best is None or len(census.channels_with_ids()) < 2:
        return None
    others = ", ".join(c for c in census.channels_with_ids() if c != best.channel)
    _warn(f"{label}: camera on channel {best.channel} ({best.describe()}); the protocol's "
          f"IDs on channel(s) {others} are other nodes' traffic")
    return best.channel


def _decode_file(args: argparse.Namespace, decoder: Any, label: str, source: Any,
                 emit: Any, run: _Run, name_re: re.Pattern[str] | None) -> None:
    """One log's records: ``frame_index`` and (unless ``--absolute-time``) ``time`` count
    from the file's start; frames of other nodes are counted, not decoded (C10)."""
    camera = _camera(args, label)
    channel, want_id, errors_only = args.channel, args.id, args.errors_only
    absolute = args.absolute_time
    decode, known, other = decoder.decode, decoder.by_id, run.other
    decoder.reset()
    origin: float | None = None
    index = -1
    for msg in source:
        index += 1
        if origin is None:
            origin = msg.timestamp
        ch = str(msg.channel)
        if channel is not None and ch != channel:
            run.skipped_channels.add(ch)
            continue
        fid = msg.arbitration_id
        if want_id is not None and fid != want_id:
            continue
        run.kept += 1
        if msg.is_extended_id or fid not in known or (camera is not None and ch != camera):
            other[fid] += 1
            continue
        rec = decode(msg, index)
        if name_re is not None and not name_re.search(rec["name"]):
            continue
        if rec["errors"]:
            run.bad += 1
        elif errors_only:
            continue
        if not absolute and rec["time"] is not None and origin is not None:
            rec["time"] = round(rec["time"] - origin, 6)
        rec["file"] = label
        emit(rec)
    run.frames += index + 1


def _decode_records(args: argparse.Namespace, decoder: Any,
                    name_re: re.Pattern[str] | None) -> int:

    emit, close = _record_sink(args, decoder)
    run = _Run()
    several = len(args.logs) > 1
    try:
        for label, source in _sources(args):
            if several and not (args.json or args.csv or args.parquet):
                print(f"=== {label}")
            try:
                _decode_file(args, decoder, label, source, emit, run, name_re)
            except TruncatedInputError as exc:
                run.truncated.append(str(exc))
            except KeyboardInterrupt:  # a live bus: stop, keep what was decoded
                pass
    finally:
        close()
    if run.frames == 0 and not run.truncated:
        raise InputError("no CAN frames in the input")
    if run.kept == 0 and args.channel is not None and not run.truncated:
        raise InputError(f"no CAN frames on channel {args.channel} (the channels are: "
                          f"{', '.join(sorted(run.skipped_channels)) or 'none'})")
    if run.other:
        ids = ", ".join(f"0x{k:X}" for k in sorted(run.other)[:8])
        more = f" and {len(run.other) - 8} more" if len(run.other) > 8 else ""
        _warn(f"other nodes' traffic, not decoded: {sum(run.other.values())} frames "
              f"(IDs {ids}{more}; --stats lists them)")
    for line in run.truncated:  # one line each, as an error is
        print(f"eyeq-spi can decode: {line}", file=sys.stderr)
    return 1 if run.bad or run.truncated else 0


def _decode(args: argparse.Namespace) -> int:
    from eyeq_spi.can.decode import CanDecoder

    name_re = _decode_args(args)
    decoder = CanDecoder(args.protocol)
    if args.stats:
        return _decode_stats(args, decoder, name_re)
    return _decode_records(args, decoder, name_re)


def run(args: argparse.Namespace) -> int:
    return int({"compare": _compare, "dbc": _dbc, "decode": _decode}[args.can_command](args))
