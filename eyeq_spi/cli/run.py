"""``eyeq-spi demo``, ``eyeq-spi sim`` and ``eyeq-spi host``: the three ways of running the
emulator (the loops of sim and host are :func:`eyeq_spi.live.serve` and
:func:`eyeq_spi.live.drive`), and the live view they show on a terminal."""

from __future__ import annotations

import argparse
import contextlib
import functools
import sys
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from eyeq_spi import garbage
from eyeq_spi.cli import args as ca
from eyeq_spi.cli import options as opt

DESCRIPTIONS = {
    "demo": "Bring a simulated EyeQ4 up to Running Vision with the host emulator, in one "
    "process, over the real link and transport. Exit 0 only if Running Vision was reached and "
    "held.",
    "sim": "The simulated EyeQ in real time. It prints LISTEN URL (or PTY PATH) on stderr as "
    "soon as it waits for a host: hand exactly that URL to eyeq-spi host --port. It serves one "
    "host after another (each connection is a power-up) and ends with one summary: per host "
    "served and in total.",
}
_DAY = f"(0, {opt.DAY_S:g}]"


def add_parser(sub: Any, name: str, help: str) -> None:
    """``demo``, ``sim`` or ``host``."""
    parser = sub.add_parser(name, help=help, description=DESCRIPTIONS.get(name))
    if name == "demo":
        parser.add_argument("--duration", type=opt.seconds, default=10.0,
                       help=f"seconds, {_DAY} (default 10)")
        parser.add_argument("--virtual-time", action="store_true",
                       help="run as fast as the CPU allows instead of in real time")
        parser.add_argument("--nvm", metavar="FILE", type=ca.output_file,
                       help="the host's NVM as a JSON file, read at the start and written "
                       "atomically: the next run starts with the calibration it learned "
                       "(default: in memory, empty)")
    elif name == "sim":
        ca.add_endpoints(parser, parser.add_mutually_exclusive_group(required=True),
                         listen="listen here for the host (port 0: any free port); or our SPI "
                         "channels, MASTER_URL,SLAVE_URL or a bench.toml (docs/bench.md)",
                         pty="open a pty and print its path; the host opens it as a serial port")
        parser.add_argument("--duration", type=opt.seconds,
                       help="stop after S seconds (default: never)")
        parser.add_argument("--accept-timeout", type=opt.seconds, default=60.0,
                       help=f"seconds to wait for the host, {_DAY} (default 60)")
    else:
        parser.add_argument("--port", required=True, metavar="URL", type=ca.connect_address,
                       help="the EyeQ: tcp://HOST:PORT as eyeq-spi sim prints it (socket:// "
                       "too), rfc2217://HOST:PORT, a tty or pty path, or our SPI channels, "
                       "MASTER_URL,SLAVE_URL or a bench.toml (docs/bench.md)")
        parser.add_argument("--nvm", metavar="FILE", type=ca.output_file,
                       help="NVM file, JSON, written atomically (default: in memory)")
        parser.add_argument("--duration", type=opt.seconds, default=10.0,
                       help=f"seconds, {_DAY} (default 10)")
        parser.add_argument("--exit-when-running", action="store_true",
                       help="stop as soon as Running Vision is reached")
        parser.add_argument("--reconnect", action="store_true",
                       help="wait for the EyeQ at the start and whenever the link is lost, "
                       "and run the bring-up again")
    opt.include(parser, opt.json_out())
    if name != "sim":
        opt.include(parser, opt.foxglove())
    if name != "demo":
        opt.include(parser, opt.rt_priority())
    opt.include(parser, opt.scenario(name))


def run(args: argparse.Namespace) -> int:
    if args.command == "demo":
        return run_demo(args)
    if args.command == "sim":
        opt.refuse_inapplicable(args, [opt.EYEQ], "sim")
        return run_sim(args)
    opt.refuse_inapplicable(args, [opt.HOST], "host: the EyeQ at --port decides")
    return run_host(args)


FATAL_22_NOTE = (
    "Fatal_Error 22 = the EyeQ's EEPROM does not match the intrinsic calibration (0x84) the "
    "host sent from its NVM. Expected on a first run: the NVM is empty, so the host reads the "
    "EEPROM into the NVM and resets the EyeQ (§7.1.3, decision I2). --nvm FILE keeps the NVM "
    "for the next run."
)


def _stderr_width() -> int:
    """The width of the terminal on stderr, at most 100 (longer lines are folded)."""
    import os

    try:
        cols = os.get_terminal_size(sys.stderr.fileno()).columns
    except (OSError, ValueError, AttributeError):
        cols = 0
    return max(40, min(100, cols)) if cols else 100  # 0: a terminal that does not say


class LiveView:
    """On a TTY: state transitions as they happen and message rates once a second, in seconds
    since the run started (a host on the wall clock has its start subtracted), each line folded
    to the terminal's width; the first FATAL_22 gets an explanation."""

    def __init__(self, enabled: bool, say: Callable[[str], None] | None = None) -> None:
        self.enabled = enabled
        self.say = say or (lambda line: print(line, file=sys.stderr))
        self.width = _stderr_width()
        self.shown = 0
        self.last_counts: Counter[str] = Counter()
        self.last_t = 0.0
        self.origin: float | None = None
        self.explained = False
        self.last_live: set[str] = set()

    def _print(self, line: str, indent: int = 11) -> None:
        """A line of the live view, folded between words to the terminal's width (continuation
        lines indented past the time stamp), never cut."""
        if len(line) > self.width:
            import textwrap

            lead = " " * (len(line) - len(line.lstrip()))
            line = textwrap.fill(line.strip(), self.width, initial_indent=lead,
                                 subsequent_indent=" " * max(indent, len(lead)),
                                 break_long_words=False, break_on_hyphens=False)
        self.say(line)

    @functools.cached_property
    def periodic(self) -> set[str]:
        """The messages the spec gives a nominal rate (seed 004's message table)."""
        from eyeq_spi.catalog.messages import catalog

        return {m.name for m in catalog().messages if m.rate_hz}

    def update(self, host: Any, now: float) -> None:
        if not self.enabled:
            return
        host_now = float(getattr(host, "now", 0.0) or 0.0)
        if self.origin is None and host_now:  # the host has seen its first event
            self.origin = host_now - now if abs(host_now - now) > 1.0 else 0.0
        origin = self.origin or 0.0
        for transition in host.transitions[self.shown:]:
            detail = f"  {transition.detail}" if getattr(transition, "detail", "") else ""
            self._print(f"[{transition.time - origin:8.3f}] {transition.src.value:>17s} "
                        f"--{transition.event.value}--> {transition.dst.value}{detail}")
            if transition.event.value == "FATAL_22" and not self.explained:
                self.explained = True
                self._print(" " * 11 + FATAL_22_NOTE)
        self.shown = len(host.transitions)
        if now - self.last_t >= 1.0:
            counts = Counter(host.counters.received)
            dt = now - self.last_t
            rates = {k: (v - self.last_counts.get(k, 0)) / dt for k, v in counts.items()}
            # a boot status or a MESP reply is no stream
            live = {k: r for k, r in rates.items() if r > 0 and k in self.periodic}
            line = f"[{now:8.3f}] {host.state.value:14s} rx {sum(live.values()):6.1f} msg/s"
            if live:
                slow = min(live, key=lambda k: live[k])
                name = slow.replace("EYEQ_", "").replace("_MSG", "")
                line += f" in {len(live)} streams, slowest {name} {live[slow]:.1f} Hz"
            stopped = sorted(k.replace("EYEQ_", "").replace("_MSG", "")
                             for k in self.last_live if k not in live)
            if stopped:
                line += f"; stopped: {', '.join(stopped)}"
            self._print(line)
            self.last_counts, self.last_t = counts, now
            self.last_live = {k for k, r in live.items() if r >= 2.0}  # periodic streams


def _on_sigterm() -> None:
    """SIGTERM ends ``demo``, ``host`` and ``sim`` like Ctrl-C: cleanly, with the summary."""
    import signal

    with contextlib.suppress(ValueError):  # not the main thread (tests)
        signal.signal(signal.SIGTERM, signal.default_int_handler)


LONG_DEMO_S = 20.0  # demos this long or longer show a progress bar on a terminal


def run_demo(args: argparse.Namespace) -> int:
    from eyeq_spi.cli.progress import JobProgress
    from eyeq_spi.emulator import summary
    from eyeq_spi.summary import ClockedAcks, ack_latency_ms

    emu, writer = opt.build_demo(args)
    collector = contextlib.ExitStack()
    acks = None
    if not args.virtual_time:
        # in real time the link's deadlines are read on the clock: no first-time codec build
        # and no full collection may delay an ACK past ackTimeout (the live sim and host warm
        # up, and collect only between bursts, the same way)
        emu.host.warm_up()
        emu.sim.warm_up()
        collector.enter_context(garbage.paused(freeze=True))
        # the summary's ACK latencies are readings of the clock too
        acks = emu.runner.tap = ClockedAcks(time.monotonic, then=emu.runner.tap)
    can_out = opt.can_output(args, emu.host, emu.runner)  # --can-out: the CAN gateway
    live = opt.foxglove_feed(args, emu.host)
    _on_sigterm()
    done_s = 0.0
    interrupted = False
    # a long demo shows how far it is (run time, s); the live lines print above the bar
    long_run = args.duration >= LONG_DEMO_S and not args.json
    try:
        with JobProgress("demo", args.duration, unit="s of run time",
                         enabled=None if long_run else False) as bar:
            view = LiveView(sys.stderr.isatty() and not args.json, say=bar.print)
            while done_s < args.duration:
                step = min(0.25, args.duration - done_s)
                emu.run_for(step, realtime=not args.virtual_time)
                if not args.virtual_time:
                    garbage.collect()  # the young generations, well under a millisecond
                done_s += step
                view.update(emu.host, emu.runner.now)
                bar.update(round(done_s, 2))
    except KeyboardInterrupt:
        interrupted = True
    finally:
        collector.close()
        emu.host.nvm.save()  # --nvm: the ignition count and what the run learned
        if writer is not None:
            writer.close()
        if can_out is not None:
            can_out.close()  # a log file is complete when the command returns
        opt.foxglove_close(live)
    out = summary(emu, interrupted=interrupted)
    if acks is not None:
        out["ack_latency_ms"] = ack_latency_ms(acks.hist)
    if can_out is not None:
        out["can"] = can_out.summary()
    opt.print_summary(out, args.json)
    return 0 if out["ok"] else 1


def run_sim(args: argparse.Namespace) -> int:
    """Serve one host after another until ``--duration`` ends or we are interrupted: one
    simulated EyeQ, and every new connection powers it up (boot status first; ``--boot-fail N``
    counts boots across connections)."""
    from eyeq_spi.live import serve
    from eyeq_spi.phy.address import is_spi
    from eyeq_spi.phy.base import open_listener
    from eyeq_spi.sim.eyeq import SimulatedEyeQ

    # bad options fail here, before anybody connects
    eyeq = SimulatedEyeQ(opt.sim_config(args))
    eyeq.warm_up()
    if args.pty:
        from eyeq_spi.phy.pty import PtyAdapter

        adapter: Any = PtyAdapter()
        address = adapter.path
        print(f"PTY {address}", file=sys.stderr, flush=True)  # stdout: the summary only
    else:
        adapter = open_listener(args.listen, timeout=args.accept_timeout)
        address = adapter.url
        print(f"LISTEN {address}", file=sys.stderr, flush=True)
    if is_spi(address):  # the host is on the wires already: nothing to hand over
        print("eyeq-spi sim: on the SPI lines; the host runs on the other side's channels",
              file=sys.stderr, flush=True)
    else:  # the exact command that connects a host
        print(f"eyeq-spi sim: waiting for a host: eyeq-spi host --port {address}",
              file=sys.stderr, flush=True)
    _on_sigterm()
    out = serve(eyeq, adapter, duration=args.duration, accept_timeout=args.accept_timeout,
                address=address, rt_priority=args.rt_priority,
                capture=opt.capture_writer(args))
    out["spi"] = adapter.line_report()  # on SPI lines: the reply latency measured
    opt.print_summary(out, args.json)
    return 0 if out["ok"] else 1


def _open_or_say(args: argparse.Namespace) -> Any:
    """Connect to ``--port``; with ``--reconnect`` the wait above already took ``--duration``."""
    from eyeq_spi.errors import AdapterError
    from eyeq_spi.phy.base import open_url

    try:
        return open_url(args.port)
    except AdapterError as exc:
        if args.reconnect:
            raise AdapterError(f"no EyeQ answered at {args.port} within --duration "
                               f"{args.duration:g} s ({exc})") from None
        raise


def run_host(args: argparse.Namespace) -> int:
    from eyeq_spi.host.host import HostEmulator
    from eyeq_spi.live import drive, reopen
    from eyeq_spi.phy.address import parse_connect
    from eyeq_spi.phy.base import open_url

    host_cfg, nvm, scenario = opt.host_parts(args)
    host = HostEmulator(host_cfg, nvm=nvm, scenario=scenario, keep_rx_times=False)
    host.warm_up()

    used: list[Any] = []  # every adapter of the run, the reconnected ones too

    def again(until: float) -> Any:
        used.append(reopen(lambda: open_url(args.port), until))
        return used[-1]

    # --reconnect: the EyeQ may not be there yet (a sim still starting, a camera powering up)
    adapter: Any = ((again(time.monotonic() + args.duration) if args.reconnect else None)
                    or _open_or_say(args))
    used.append(adapter)
    _on_sigterm()
    view = LiveView(sys.stderr.isatty() and not args.json)

    live = opt.foxglove_feed(args, host)
    try:
        out = drive(host, adapter, duration=args.duration,
                    address=parse_connect(args.port, check_path=False).display,
                    reopen_adapter=again if args.reconnect else None,
                    exit_when_running=args.exit_when_running, rt_priority=args.rt_priority,
                    capture=opt.capture_writer(args),
                    attach=lambda runner: opt.can_output(args, host, runner),
                    on_step=view.update)
    finally:
        opt.foxglove_close(live)
    out["spi"] = used[-1].line_report() if used[-1] is not None else None
    opt.print_summary(out, args.json)
    return 0 if out["ok"] else 1
