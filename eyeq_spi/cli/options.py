"""The option groups several commands share, as argparse parent parsers, the one conversion of
parsed options into the library's config objects, and the run summary's printing. Every numeric
limit lives in :data:`LIMITS`; an option of one side only is refused where that side does not
run (:func:`refuse_inapplicable`).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Collection
from typing import Any

from eyeq_spi import io as formats
from eyeq_spi.cli import args as ca
from eyeq_spi.errors import EyeqError, UsageError

# -- capture formats (the one list: dissect, export, replay, plot, monitor) ---------------------
FORMATS = formats.readers()  # the io registry's capture readers, in detection order
DIRECTIONS = ("h2e", "e2h")

# -- limits: (lo, hi) of every bounded option, checked by its argparse type ---------------------
LIMITS: dict[str, tuple[int, int]] = {
    "seed": (0, 2**32 - 1), "objects": (0, 15), "signs": (0, 20), "light_spots": (0, 15),
    "boot_fail": (0, 1000), "rt_priority": (0, 99),
    "dissect_jobs": (0, 1024),  # dissect --jobs (0: one per CPU)
    "batch_jobs": (1, 1024), "local_cluster": (1, 256),  # batch --jobs, --local-cluster
}
DAY_S = 86_400.0  # durations and instants: (0, DAY_S] seconds
LINK_TIMEOUT_MS = 60_000.0  # --ack-timeout, --transmit-timeout: (0, this] ms
REPLY_DELAY_S = 3600.0  # --reply-delay: [0, this] s


def limited(key: str) -> ca.Type:
    """The argparse type of a bounded integer option, from :data:`LIMITS`."""
    lo, hi = LIMITS[key]
    return ca.integer(lo, hi)


seconds = ca.number(0, DAY_S, lo_open=True, unit="s")
link_ms = ca.number(0, LINK_TIMEOUT_MS, lo_open=True, unit="ms")


def _parent() -> argparse.ArgumentParser:
    return argparse.ArgumentParser(add_help=False)


def include(parser: argparse.ArgumentParser, *parents: argparse.ArgumentParser) -> None:
    """What ``ArgumentParser(parents=...)`` does, at this point of ``parser``'s options: the
    shared options come where ``--help`` has always listed them, not first."""
    for parent in parents:
        parser._add_container_actions(parent)
        parser._defaults.update(parent._defaults)


# -- single shared options ----------------------------------------------------------------------

SW_HELP = ("SW release of the traffic (default: the one the capture records or shows, else the "
           "newest)")


def add_sw(group: Any, help: str = SW_HELP) -> None:
    """``--sw``: a release that ``specs/`` describes, any spelling (``9.0``, ``8.1``, ``sw5``)."""
    group.add_argument("--sw", type=ca.sw_release, help=help)


def json_out(help: str = "end with one JSON object") -> argparse.ArgumentParser:
    parser = _parent()
    parser.add_argument("--json", action="store_true", help=help)
    return parser


def _foxglove_address(text: str) -> str:
    from eyeq_spi.foxglove.server import parse_address

    try:
        host, port = parse_address(text)
    except EyeqError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return f"{host}:{port}"


def foxglove() -> argparse.ArgumentParser:
    """``--foxglove [HOST:PORT]``: serve the run live to Foxglove (the [foxglove] extra)."""
    parser = _parent()
    parser.add_argument("--foxglove", nargs="?", const="127.0.0.1:8765", type=_foxglove_address,
                        metavar="HOST:PORT", help="serve the EyeQ's scene, plots and log live to "
                        "Foxglove over a WebSocket (default 127.0.0.1:8765; port 0: any free port; "
                        "the address is printed on stderr; needs the [foxglove] extra)")
    return parser


def foxglove_feed(args: argparse.Namespace, host: Any) -> Any:
    """``--foxglove``: a started server with ``host`` published to it (a
    :class:`~eyeq_spi.foxglove.live.HostFeed`), or None."""
    sink = serve_foxglove(args)
    if sink is None:
        return None
    from eyeq_spi.foxglove.live import HostFeed

    return HostFeed(host, sink)


def foxglove_close(live: Any) -> None:
    """Stop ``--foxglove``'s server; say on stderr what it published."""
    if live is None:
        return
    live.feed.sink.close()
    print(f"FOXGLOVE {live.feed.sink.url}: {live.describe()}", file=sys.stderr, flush=True)


def serve_foxglove(args: argparse.Namespace) -> Any:
    """``--foxglove``: the started server (a Foxglove sink), its address said on stderr; or
    None."""
    address = getattr(args, "foxglove", None)
    if not address:
        return None
    from eyeq_spi.foxglove.server import ServerSink

    sink = ServerSink(address, name=f"eyeq-spi {args.command}")
    print(f"FOXGLOVE {sink.url} (in Foxglove: Open connection, Foxglove WebSocket, this URL; "
          "the layout: the .layout.json that export --mcap writes, or "
          "docs/foxglove.layout.json)", file=sys.stderr, flush=True)
    return sink


def print_summary(out: dict[str, Any], as_json: bool) -> None:
    """The JSON object (``--json``) or a readable text block: same content."""
    if as_json:
        print(json.dumps(out, sort_keys=True), flush=True)
        return
    from eyeq_spi.summary import format_summary

    print(format_summary(out), flush=True)


def rt_priority(what: str = "ACKs") -> argparse.ArgumentParser:
    """``--rt-priority N``: SCHED_FIFO for the live run (``eyeq_spi.runner.sched``)."""
    lo, hi = LIMITS["rt_priority"]
    parser = _parent()
    parser.add_argument("--rt-priority", type=limited("rt_priority"), default=10, metavar="N",
                        help=f"SCHED_FIFO priority {lo + 1}..{hi} so that {what} meet the 10 ms "
                        "ackTimeout on a busy machine; 0: ordinary scheduling (default 10; falls "
                        "back when refused)")
    return parser


# -- capture input ------------------------------------------------------------------------------

def capture_input(*, spi: bool = True,
                  direction_help: str = "channel of an input without directions",
                  format_help: str = "skip detection",
                  sw_help: str | None = SW_HELP) -> argparse.ArgumentParser:
    """``--format``, ``--direction``, ``--sw`` and (``spi``) the logic-analyzer options."""
    parser = _parent()
    parser.add_argument("--format", choices=FORMATS, help=format_help)
    parser.add_argument("--direction", choices=DIRECTIONS, help=direction_help)
    if sw_help is not None:
        add_sw(parser, sw_help)
    if spi:
        add_spi_arguments(parser)
    return parser


def add_spi_arguments(parser: Any) -> None:
    """How a logic-analyzer capture maps onto the two SPI channels (``logic.options``)."""
    group = parser.add_argument_group("logic-analyzer inputs (saleae2, saleae1, vcd)")
    group.add_argument("--spi-mode", type=int, choices=(0, 1, 2, 3),
                       help="SPI mode (default 1: §6 POLARITY_0_PHASE_1)")
    group.add_argument("--bit-order", choices=("msb_first", "lsb_first"),
                       help="bit order of each byte on the wire (default msb_first)")
    group.add_argument("--channel-map", metavar="MAP",
                       help="which capture channel carries each direction: h2e=NAME[:LINE],"
                       "e2h=NAME[:LINE] (NAME: Saleae analyzer name or VCD channel prefix, empty "
                       "for the only one; LINE mosi|miso). Default: channels named h2e/e2h, MOSI")
    group.add_argument("--signals", action="append", default=[],
                       metavar="CHANNEL=CS,CLK,MOSI[,MISO]",
                       help="VCD signal names of a channel (repeatable; default <channel>_cs ...)")


def spi_options(args: argparse.Namespace) -> Any:
    """The SPI options of a logic-analyzer input as :class:`eyeq_spi.logic.options.SpiOptions`."""
    from eyeq_spi.logic.options import SpiOptions, parse_channel_map, parse_signals

    kw: dict[str, Any] = {"direction": getattr(args, "direction", None)}
    if getattr(args, "spi_mode", None) is not None:
        kw["mode"] = args.spi_mode
    if getattr(args, "bit_order", None):
        kw["bit_order"] = args.bit_order
    if getattr(args, "channel_map", None):
        kw["channel_map"] = parse_channel_map(args.channel_map)
    if getattr(args, "signals", None):
        kw["signals"] = parse_signals(args.signals)
    return SpiOptions(**kw)


# -- options of one side only: the one refusal mechanism ----------------------------------------

EYEQ, HOST = "eyeq", "host"
_SIDE_NAMES = {EYEQ: "the simulated EyeQ (demo, sim)", HOST: "the host emulator (demo, host)"}
SIDE_OF: dict[str, frozenset[str]] = {}  # dest -> the sides it applies to (filled below)


class _Given(argparse.Action):
    """Stores like ``store``, ``store_true`` or ``append`` (its ``const``) and notes in
    ``namespace._given`` that the option was given."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        if self.const == "store_true":
            values = True
        elif self.const == "append":
            values = [*(getattr(namespace, self.dest, None) or []), values]
        setattr(namespace, self.dest, values)
        namespace._given = {*(getattr(namespace, "_given", None) or ()), self.dest}


def _side_option(group: Any, sides: Collection[str], shown: bool, *flags: str,
                 **kw: Any) -> None:
    """An option of ``sides``; hidden from ``--help`` where none of them runs (``shown`` False),
    and refused there by :func:`refuse_inapplicable` if given."""
    kind = kw.pop("action", None) or "store"
    if kind == "store_true":
        kw.update(nargs=0, default=kw.get("default", False))
    if not shown:  # refused whatever its value: the refusal, not a value check, is the error
        kw.update(help=argparse.SUPPRESS, type=None, choices=None)
    dest = group.add_argument(*flags, action=_Given, const=kind, **kw).dest
    SIDE_OF[dest] = frozenset(sides)


def refuse_inapplicable(args: argparse.Namespace, sides: Collection[str], where: str) -> None:
    """A usage error for the first option given that applies to none of ``sides`` (``where``
    names what runs instead, e.g. ``sim`` or ``monitor --replay``)."""
    for dest in sorted(getattr(args, "_given", None) or ()):
        own = SIDE_OF.get(dest, frozenset())
        if own and not own & set(sides):
            whose = (f"applies to {_SIDE_NAMES[next(iter(own))]}" if len(own) == 1
                     else "applies to a live emulator (demo, sim, host)")
            raise UsageError(f"argument --{dest.replace('_', '-')}: {whose}, not to {where}")


# -- scenario, link and faults (demo, sim, host, monitor) ---------------------------------------

def scenario(side: str = "demo") -> argparse.ArgumentParser:
    """Scenario, link and fault options of ``demo`` (both sides), ``sim`` (the simulated EyeQ),
    ``host`` (the host emulator) and ``monitor`` (both, refused per source at run time)."""
    eyeq, host = side != "host", side != "sim"
    both = (EYEQ, HOST)
    parser = _parent()
    group = parser.add_argument_group("scenario")
    _side_option(group, [EYEQ], eyeq, "--seed", type=limited("seed"), default=1,
                 help="random seed of the scene, 0..2^32-1 (default 1)")
    add_sw(group, "SW release both sides speak, e.g. 9.0 or 8.1 (default: newest in specs/)")
    _side_option(group, [HOST], host, "--speed", type=_speed, default=25.0, metavar="M_S",
                 help="constant drive speed, m/s, in vehicleVelocity's range (default 25)")
    _side_option(group, [HOST], host, "--scenario", metavar="CSV", type=ca.input_file,
                 help="vehicle signals from a CSV: time and host_vehicle_state_t members")
    for dest, default, what in (("objects", 8, "tracked objects"), ("signs", 4, "traffic signs"),
                                ("light_spots", 4, "light spots")):
        _side_option(group, [EYEQ], eyeq, "--" + dest.replace("_", "-"), type=limited(dest),
                     default=default, help=f"{what}, {LIMITS[dest][0]}..{LIMITS[dest][1]} "
                     f"(default {default})")
    _side_option(group, [HOST], host, "--camera-only-aeb", action="store_true",
                 help="send IPB/PCW (0x78/0x79)")
    span = f"(0, {LINK_TIMEOUT_MS:g}]"
    _side_option(group, both, True, "--ack-timeout", type=link_ms, metavar="MS",
                 help=f"link ackTimeout in ms, {span} (default 10, seed §6); raise it for slow "
                 "bridges")
    _side_option(group, both, True, "--transmit-timeout", type=link_ms, metavar="MS",
                 help=f"link transmitTimeout in ms, {span} (default 25, §6)")
    _side_option(group, both, True, "--capture", metavar="FILE.pcapng", type=ca.output_file,
                 help="write every SPI transfer of both channels to a pcapng capture")
    _side_option(group, [HOST], host, "--can-out", metavar="TARGET",
                 help="Mobileye CAN output from the decoded DASP data: virtual, "
                 "INTERFACE:CHANNEL (socketcan:vcan0) or a .blf/.asc/.mf4/.log/.trc file")
    _side_option(group, [HOST], host, "--can-protocol", choices=("extlog2", "me8"),
                 default="extlog2", help="CAN protocol of --can-out (default extlog2)")
    faults = parser.add_argument_group("faults (simulated EyeQ)") if eyeq else group
    lo, hi = LIMITS["boot_fail"]
    _side_option(faults, [EYEQ], eyeq, "--boot-fail", type=limited("boot_fail"), default=0,
                 metavar="N", help=f"the first N boots ({lo}..{hi}) report failing test bits")
    _side_option(faults, [EYEQ], eyeq, "--boot-test-bits", type=ca.boot_test_bits, default=0x0002,
                 metavar="BITS", help="TestResults of a failing boot: 0x0001..0xFFFF or bit "
                 "names joined with | (default 0x0002)")
    _side_option(faults, [EYEQ], eyeq, "--corrupt-eeprom", action="store_true",
                 help="EEPROM CRC does not match")
    _side_option(faults, [EYEQ], eyeq, "--fatal", type=ca.fatal_code, metavar="CODE",
                 help="force Fatal_Error CODE in 0x41: a number or name of enum fatal_error "
                 "(22 = INTRINSIC_CALIBRATION_MISMATCH)")
    _side_option(faults, [EYEQ], eyeq, "--reply-delay", type=ca.number(0, REPLY_DELAY_S, unit="s"),
                 default=0.0, metavar="S",
                 help=f"delay every MESP reply by S seconds, 0..{REPLY_DELAY_S:g}")
    _side_option(faults, [EYEQ], eyeq, "--drop-reply", action="append", default=[],
                 type=ca.drop_reply, metavar="FUNCTION[:N]",
                 help="drop the first N (default 1) replies to a MESP function (name, any case, "
                 "or SERVICE/FUNCTION such as 0x05/0x04)")
    _side_option(faults, [EYEQ], eyeq, "--reset-at", type=seconds, metavar="T",
                 help=f"the EyeQ resets at time T s, (0, {DAY_S:g}]")
    _side_option(faults, [EYEQ], eyeq, "--stop-dasp", action="append", default=[],
                 type=ca.stop_dasp, metavar="MESSAGE[@T]",
                 help="stop sending a DASP message (name, any case, or data ID such as 0xE4) "
                 "at T s (default 0)")
    return parser


def _speed(text: str) -> float:
    """``--speed``: within host_vehicle_state_t.vehicleVelocity's range in specs/."""
    cat = ca.catalogue()
    var = cat.structs["host_vehicle_state_t"].variant_for(cat.default_sw)
    lo, hi = -20.0, 100.0
    for member in var.members if var else ():
        if member.name == "vehicleVelocity" and member.min is not None and member.max is not None:
            lo, hi = float(member.min), float(member.max)
    return float(ca.number(lo, hi, unit="m/s")(text))


# -- Namespace -> library config ----------------------------------------------------------------

def _seconds(ms: float | None) -> float | None:
    return None if ms is None else ms / 1000.0


def sim_config(args: argparse.Namespace) -> Any:
    """The simulated EyeQ's :class:`~eyeq_spi.sim.config.SimConfig` from the options."""
    from eyeq_spi.sim.config import SimConfig

    drops: dict[str, int] = {}
    for fn, count in args.drop_reply:  # (name, N) from args.drop_reply
        drops[fn] = drops.get(fn, 0) + count
    stops: dict[str, float] = dict(args.stop_dasp)  # (name, T) from args.stop_dasp
    return SimConfig(
        sw=args.sw, seed=args.seed, objects=args.objects, signs=args.signs,
        light_spots=args.light_spots, boot_failures=args.boot_fail,
        boot_test_failures=args.boot_test_bits, corrupt_eeprom_crc=args.corrupt_eeprom,
        fatal_error=args.fatal, reply_delay=args.reply_delay, drop_replies=drops,
        reset_at=args.reset_at, stop_dasp=stops,
        ack_timeout=_seconds(args.ack_timeout), transmit_timeout=_seconds(args.transmit_timeout),
    )


def host_parts(args: argparse.Namespace) -> tuple[Any, Any, Any]:
    """The host emulator's config, NVM and scenario from the options."""
    from eyeq_spi.host.host import HostConfig
    from eyeq_spi.host.nvm import Nvm
    from eyeq_spi.host.scenario import ConstantDrive, CsvScenario

    if args.scenario:
        from eyeq_spi.catalog.messages import catalog

        cat = catalog()
        variant = cat.structs["host_vehicle_state_t"].variant_for(cat.sw(args.sw))
        members = {m.name for m in variant.members} if variant else set()
        scenario_: Any = CsvScenario(args.scenario, allowed=members)
    else:
        scenario_ = ConstantDrive(args.speed)
    nvm = Nvm(getattr(args, "nvm", None))
    cfg = HostConfig(sw=args.sw, camera_only_aeb=args.camera_only_aeb,
                     ack_timeout=_seconds(args.ack_timeout),
                     transmit_timeout=_seconds(args.transmit_timeout))
    return cfg, nvm, scenario_


def capture_writer(args: argparse.Namespace) -> Any:
    """``--capture FILE``: the pcapng writer of both channels, or None."""
    if not args.capture:
        return None
    from eyeq_spi.capture.pcapng_io import CaptureWriter

    # a virtual-time demo stamps the simulation's schedule; every other run reads the clock
    time_base = "virtual" if getattr(args, "virtual_time", False) else "monotonic"
    return CaptureWriter(args.capture, getattr(args, "sw", None), time_base=time_base)


def can_output(args: argparse.Namespace, host: Any, runner: Any) -> Any:
    """``--can-out TARGET [--can-protocol P]``: the CAN gateway on ``host``, or None."""
    target = getattr(args, "can_out", None)
    if not target:
        return None
    from eyeq_spi.can.sinks import attach

    return attach(host, runner, target=target,
                  protocol=getattr(args, "can_protocol", None) or "extlog2")


def capture_tap(writer: Any, clock: Callable[[], float] | None) -> Callable[..., None]:
    """The emulator's tap onto the ``--capture`` writer: node 0 (the host) sends ``h2e``. With
    ``clock`` (real time) a transfer is stamped with the clock's reading when it was handed
    over, else with the schedule's instant (virtual time)."""
    origin: float | None = None  # the clock's reading at the schedule's 0

    def tap(node: int, time_s: float, transfer: bytes) -> None:
        nonlocal origin
        if clock is not None:
            now = clock()
            origin = now - time_s if origin is None else origin
            time_s = now - origin
        writer.write(DIRECTIONS[node], time_s, transfer)
    return tap


def build_demo(args: argparse.Namespace) -> tuple[Any, Any]:
    """The host emulator and the simulated EyeQ of ``demo`` (and ``monitor --demo``) wired
    in one process, with the ``--capture`` writer tapping both channels (or None)."""
    from eyeq_spi.emulator import build

    host_cfg, nvm, scenario_ = host_parts(args)
    writer = capture_writer(args)
    # real time: the capture says when each transfer happened (its clock is in the file)
    realtime = not getattr(args, "virtual_time", False)
    tap = None if writer is None else capture_tap(writer, time.monotonic if realtime else None)
    emu = build(sim_config=sim_config(args), host_config=host_cfg, nvm=nvm, scenario=scenario_,
                keep_rx_times=False, tap=tap)
    return emu, writer
