"""``eyeq-spi demo``, ``eyeq-spi sim`` and ``eyeq-spi host``: shared fault and scenario options,
and the three ways of running the emulator."""

from __future__ import annotations

import argparse
import contextlib
import gc
import json
import sys
import time
from collections import Counter
from typing import Any

from eyeq_spi.errors import UsageError

SIDES = ("demo", "sim", "host")
_NOT_HOST = "applies to the simulated EyeQ (demo, sim), not to host: the EyeQ at --port decides"
_NOT_SIM = "applies to the host emulator (demo, host), not to sim"


def add_shared_options(p: argparse.ArgumentParser, side: str = "demo") -> None:
    """Scenario, link and fault options of ``demo`` (both sides), ``sim`` (the simulated EyeQ)
    and ``host`` (the host emulator). An option of the other side is refused, not ignored."""
    from eyeq_spi.cli import args as ca

    if side not in SIDES:
        raise ValueError(f"side must be one of {SIDES}")
    eyeq, host = side != "host", side != "sim"
    g = p.add_argument_group("scenario")
    ca.add_option(g, eyeq, _NOT_HOST, "--seed", type=ca.integer(0, 2**32 - 1), default=1,
                  help="random seed of the scene, 0..2^32-1 (default 1)")
    g.add_argument("--sw", type=ca.sw_release,
                   help="SW release both sides speak, e.g. 9.0 or 8.1 (default: newest in specs/)")
    ca.add_option(g, host, _NOT_SIM, "--speed", type=_speed, default=25.0, metavar="M_S",
                  help="constant drive speed, m/s, in vehicleVelocity's range (default 25)")
    ca.add_option(g, host, _NOT_SIM, "--scenario", metavar="CSV", type=ca.input_file,
                  help="vehicle signals from a CSV: time and host_vehicle_state_t members")
    ca.add_option(g, eyeq, _NOT_HOST, "--objects", type=ca.integer(0, 15), default=8,
                  help="tracked objects, 0..15 (default 8)")
    ca.add_option(g, eyeq, _NOT_HOST, "--signs", type=ca.integer(0, 20), default=4,
                  help="traffic signs, 0..20 (default 4)")
    ca.add_option(g, eyeq, _NOT_HOST, "--light-spots", type=ca.integer(0, 15), default=4,
                  help="light spots, 0..15 (default 4)")
    ca.add_option(g, host, _NOT_SIM, "--camera-only-aeb", action="store_true",
                  help="send IPB/PCW (0x78/0x79)")
    g.add_argument("--ack-timeout", type=ca.number(0, 60_000, lo_open=True, unit="ms"),
                   metavar="MS", help="link ackTimeout in ms, (0, 60000] (default 10, seed §6); "
                   "raise it for slow bridges")
    g.add_argument("--transmit-timeout", type=ca.number(0, 60_000, lo_open=True, unit="ms"),
                   metavar="MS", help="link transmitTimeout in ms, (0, 60000] (default 25, §6)")
    g.add_argument("--capture", metavar="FILE.pcapng", type=ca.output_file,
                   help="write every SPI transfer of both channels to a pcapng capture")
    ca.add_option(g, host, _NOT_SIM, "--can-out", metavar="TARGET",
                  help="Mobileye CAN output from the decoded DASP data: virtual, "
                  "INTERFACE:CHANNEL (socketcan:vcan0) or a .blf/.asc/.mf4/.log/.trc file")
    ca.add_option(g, host, _NOT_SIM, "--can-protocol", choices=("extlog2", "me8"),
                  default="extlog2", help="CAN protocol of --can-out (default extlog2)")
    f = p.add_argument_group("faults (simulated EyeQ)") if eyeq else g
    ca.add_option(f, eyeq, _NOT_HOST, "--boot-fail", type=ca.integer(0, 1000), default=0,
                  metavar="N", help="the first N boots (0..1000) report failing test bits")
    ca.add_option(f, eyeq, _NOT_HOST, "--boot-test-bits", type=ca.boot_test_bits, default=0x0002,
                  metavar="BITS", help="TestResults of a failing boot: 0x0001..0xFFFF or bit "
                  "names joined with | (default 0x0002)")
    ca.add_option(f, eyeq, _NOT_HOST, "--corrupt-eeprom", action="store_true",
                  help="EEPROM CRC does not match")
    ca.add_option(f, eyeq, _NOT_HOST, "--fatal", type=ca.fatal_code, metavar="CODE",
                  help="force Fatal_Error CODE in 0x41: a number or name of enum fatal_error "
                  "(22 = INTRINSIC_CALIBRATION_MISMATCH)")
    ca.add_option(f, eyeq, _NOT_HOST, "--reply-delay", type=ca.number(0, 3600, unit="s"),
                  default=0.0, metavar="S", help="delay every MESP reply by S seconds, 0..3600")
    ca.add_option(f, eyeq, _NOT_HOST, "--drop-reply", action="append", default=[],
                  type=ca.drop_reply, metavar="FUNCTION[:N]",
                  help="drop the first N (default 1) replies to a MESP function (name, any case, "
                  "or SERVICE/FUNCTION such as 0x05/0x04)")
    ca.add_option(f, eyeq, _NOT_HOST, "--reset-at", type=ca.number(0, 86_400, lo_open=True,
                  unit="s"), metavar="T", help="the EyeQ resets at time T s, (0, 86400]")
    ca.add_option(f, eyeq, _NOT_HOST, "--stop-dasp", action="append", default=[],
                  type=ca.stop_dasp, metavar="MESSAGE[@T]",
                  help="stop sending a DASP message (name, any case, or data ID such as 0xE4) "
                  "at T s (default 0)")


def _speed(text: str) -> float:
    """``--speed``: within host_vehicle_state_t.vehicleVelocity's range in specs/."""
    from eyeq_spi.cli import args as ca

    cat = ca._cat()
    var = cat.structs["host_vehicle_state_t"].variant_for(cat.default_sw)
    lo, hi = -20.0, 100.0
    for m in var.members if var else ():
        if m.name == "vehicleVelocity" and m.min is not None and m.max is not None:
            lo, hi = float(m.min), float(m.max)
    return float(ca.number(lo, hi, unit="m/s")(text))


def _ms(value: float | None, name: str) -> float | None:
    if value is None:
        return None
    if not 0 < value <= 60_000:
        raise UsageError(f"--{name} must be in (0, 60000] ms")
    return value / 1000.0


def _check_counts(args: argparse.Namespace) -> None:
    for name, hi in (("objects", 15), ("signs", 20), ("light_spots", 15)):
        v = getattr(args, name)
        if not 0 <= v <= hi:
            raise UsageError(f"--{name.replace('_', '-')} must be 0..{hi}, got {v}")


def sim_config(args: argparse.Namespace) -> Any:
    from eyeq_spi.sim.config import SimConfig

    _check_counts(args)
    drops: dict[str, int] = {}
    for fn, n in args.drop_reply:  # (name, N) from cli_args.drop_reply
        drops[fn] = drops.get(fn, 0) + n
    stops: dict[str, float] = dict(args.stop_dasp)  # (name, T) from cli_args.stop_dasp
    return SimConfig(
        sw=args.sw, seed=args.seed, objects=args.objects, signs=args.signs,
        light_spots=args.light_spots, boot_failures=args.boot_fail,
        boot_test_failures=args.boot_test_bits, corrupt_eeprom_crc=args.corrupt_eeprom,
        fatal_error=args.fatal, reply_delay=args.reply_delay, drop_replies=drops,
        reset_at=args.reset_at, stop_dasp=stops,
        ack_timeout=_ms(args.ack_timeout, "ack-timeout"),
        transmit_timeout=_ms(args.transmit_timeout, "transmit-timeout"),
    )


def host_parts(args: argparse.Namespace) -> tuple[Any, Any, Any]:
    from eyeq_spi.host.host import HostConfig
    from eyeq_spi.host.nvm import Nvm
    from eyeq_spi.host.scenario import ConstantDrive, CsvScenario

    if args.scenario:
        from eyeq_spi.spec.catalog import catalog

        cat = catalog()
        variant = cat.structs["host_vehicle_state_t"].variant_for(cat.sw(args.sw))
        members = {m.name for m in variant.members} if variant else set()
        scenario: Any = CsvScenario(args.scenario, allowed=members)
    else:
        scenario = ConstantDrive(args.speed)
    nvm = Nvm(getattr(args, "nvm", None))
    cfg = HostConfig(sw=args.sw, camera_only_aeb=args.camera_only_aeb,
                     ack_timeout=_ms(args.ack_timeout, "ack-timeout"),
                     transmit_timeout=_ms(args.transmit_timeout, "transmit-timeout"))
    return cfg, nvm, scenario


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
    """On a TTY: state transitions as they happen and message rates once a second.

    One time base: every time printed is seconds since the run started, the same clock the
    transitions carry (a host on the wall clock has its start subtracted, inferred from the
    host's own ``now`` on the first update). Every line fits the terminal (at most 100
    columns), folded between words, never cut; the first FATAL_22 gets an explanation (an empty
    NVM on a first run)."""

    def __init__(self, enabled: bool, out: Any = None, width: int | None = None) -> None:
        self.enabled = enabled
        self.out = out
        self.width = width or _stderr_width()
        self.shown = 0
        self.last_counts: Counter[str] = Counter()
        self.last_t = 0.0
        self.origin: float | None = None
        self.explained = False
        self.last_live: set[str] = set()
        self._periodic_names: set[str] | None = None

    def _print(self, line: str, indent: int = 11) -> None:
        """A line of the live view, folded between words to the terminal's width (continuation
        lines indented past the time stamp), never cut."""
        if len(line) > self.width:
            import textwrap

            lead = " " * (len(line) - len(line.lstrip()))
            line = textwrap.fill(line.strip(), self.width, initial_indent=lead,
                                 subsequent_indent=" " * max(indent, len(lead)),
                                 break_long_words=False, break_on_hyphens=False)
        print(line, file=self.out or sys.stderr)

    def _periodic(self, host: Any) -> set[str]:
        """The messages the spec gives a nominal rate (seed 004's message table)."""
        if self._periodic_names is None:
            from eyeq_spi.spec.catalog import catalog

            self._periodic_names = {m.name for m in catalog().messages if m.rate_hz}
        return self._periodic_names

    def update(self, host: Any, now: float) -> None:
        if not self.enabled:
            return
        host_now = float(getattr(host, "now", 0.0) or 0.0)
        if self.origin is None and host_now:  # the host has seen its first event
            self.origin = host_now - now if abs(host_now - now) > 1.0 else 0.0
        origin = self.origin or 0.0
        for t in host.transitions[self.shown:]:
            detail = f"  {t.detail}" if getattr(t, "detail", "") else ""
            self._print(f"[{t.time - origin:8.3f}] {t.src.value:>17s} --{t.event.value}--> "
                        f"{t.dst.value}{detail}")
            if t.event.value == "FATAL_22" and not self.explained:
                self.explained = True
                self._print(" " * 11 + FATAL_22_NOTE)
        self.shown = len(host.transitions)
        if now - self.last_t >= 1.0:
            counts = Counter(host.counters.received)
            dt = now - self.last_t
            rates = {k: (v - self.last_counts.get(k, 0)) / dt for k, v in counts.items()}
            periodic = self._periodic(host)  # a boot status or a MESP reply is no stream
            live = {k: r for k, r in rates.items() if r > 0 and k in periodic}
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


def _connect_hint(endpoint: str) -> None:
    """``sim``: the exact command that connects a host (after the LISTEN or PTY line)."""
    print(f"eyeq-spi sim: waiting for a host: eyeq-spi host --port {endpoint}", file=sys.stderr,
          flush=True)


def capture_writer(args: argparse.Namespace) -> Any:
    if not args.capture:
        return None
    from eyeq_spi.capture.pcapng_io import CaptureWriter

    return CaptureWriter(args.capture, getattr(args, "sw", None))


def _realtime_tap(writer: Any, start: float, tx: str, rx: str) -> Any:
    if writer is None:
        return None

    def tap(kind: str, t: float, transfer: bytes) -> None:
        writer.write(tx if kind == "tx" else rx, t - start, transfer)

    return tap


def _on_sigterm() -> None:
    """SIGTERM ends ``demo``, ``host`` and ``sim`` like Ctrl-C: cleanly, with the summary."""
    import signal

    def raise_interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    with contextlib.suppress(ValueError):  # not the main thread (tests)
        signal.signal(signal.SIGTERM, raise_interrupt)


def print_summary(out: dict[str, Any], as_json: bool) -> None:
    """The JSON object (``--json``) or a readable text block: same content."""
    if as_json:
        print(json.dumps(out, sort_keys=True), flush=True)
        return
    from eyeq_spi.report import format_summary

    print(format_summary(out), flush=True)


def build_demo(args: argparse.Namespace) -> tuple[Any, Any]:
    """The host emulator and the simulated EyeQ of ``demo`` (and ``monitor --demo``) wired
    in one process, with the ``--capture`` writer tapping both channels (or None)."""
    from eyeq_spi.emulator import build

    host_cfg, nvm, scenario = host_parts(args)
    writer = capture_writer(args)
    tap = None
    if writer is not None:
        def tap(node: int, t: float, transfer: bytes) -> None:
            writer.write("h2e" if node == 0 else "e2h", t, transfer)
    emu = build(sim_config=sim_config(args), host_config=host_cfg, nvm=nvm, scenario=scenario,
                keep_rx_times=False, tap=tap)
    return emu, writer


LONG_DEMO_S = 20.0  # demos this long or longer show a progress bar on a terminal


def run_demo(args: argparse.Namespace) -> int:
    from eyeq_spi.report import host_summary

    if args.duration <= 0:
        raise UsageError("--duration must be positive")
    emu, writer = build_demo(args)
    from eyeq_spi.can.sinks import attach_from_args

    can_out = attach_from_args(args, emu.host, emu.runner)  # --can-out: the CAN gateway
    from eyeq_spi.cli.progress import JobProgress

    _on_sigterm()
    t = 0.0
    interrupted = False
    # a long demo shows how far it is (run time, s); the live lines print above the bar
    long_run = args.duration >= LONG_DEMO_S and not args.json
    try:
        with JobProgress("demo", args.duration, unit="s of run time",
                         enabled=None if long_run else False) as bar:
            view = LiveView(sys.stderr.isatty() and not args.json, out=bar.lines())
            while t < args.duration:
                step = min(0.25, args.duration - t)
                emu.run_for(step, realtime=not args.virtual_time)
                t += step
                view.update(emu.host, emu.runner.now)
                bar.update(round(t, 2))
    except KeyboardInterrupt:
        interrupted = True
    finally:
        emu.host.nvm.save()  # --nvm: the ignition count and what the run learned
        if writer is not None:
            writer.close()
        if can_out is not None:
            can_out.close()  # a log file is complete when the command returns
    out = host_summary(emu.host, side="demo", elapsed=emu.runner.now, wall=emu.runner.wall_s,
                       cpu=emu.runner.cpu_s, running_since=emu.running_since,
                       left_running=emu.left_running, interrupted=interrupted, eyeq=emu.sim)
    if can_out is not None:
        out["can"] = can_out.summary()
    print_summary(out, args.json)
    return 0 if out["ok"] else 1


def run_sim(args: argparse.Namespace) -> int:
    """Serve one host after another until ``--duration`` ends or we are interrupted: one
    simulated EyeQ, and every new connection powers it up (boot status first; ``--boot-fail N``
    counts boots across connections)."""
    from eyeq_spi.errors import LinkLostError
    from eyeq_spi.phy.base import open_listener
    from eyeq_spi.report import SimSessions, sim_summary
    from eyeq_spi.runner.realtime import RealTimeRunner
    from eyeq_spi.runner.sched import realtime
    from eyeq_spi.sim.eyeq import SimulatedEyeQ

    if bool(args.listen) == bool(args.pty):
        raise UsageError("give exactly one of --listen tcp://HOST:PORT or --pty")
    cfg = sim_config(args)
    # One EyeQ for the whole run: every connection powers it up again (a new boot, counted
    # against --boot-fail), as the reset line would; bad options fail here, before anybody
    # connects
    eyeq = SimulatedEyeQ(cfg)
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
    _connect_hint(address)
    _on_sigterm()
    writer = capture_writer(args)
    clock = time.monotonic
    t0, cpu0 = clock(), time.process_time()
    end = None if args.duration is None else t0 + args.duration
    sim: Any = None
    served = SimSessions(t0)  # one summary per host served
    interrupted = False
    gc.freeze()  # the catalogue and layouts live forever: keep collections short
    rt = contextlib.ExitStack()  # real-time scheduling for the live run only
    scheduling = rt.enter_context(realtime(args.rt_priority))
    try:
        while end is None or clock() < end:
            if sim is None and clock() - t0 > args.accept_timeout:
                break
            wait = 0.5 if end is None else max(0.0, min(0.5, end - clock()))
            if not adapter.accept(wait):
                continue
            sim = eyeq
            gc.collect()
            gc.freeze()
            runner = RealTimeRunner(sim, adapter)
            runner.tap = _realtime_tap(writer, t0, "e2h", "h2e")
            sim.power_up(runner.clock())
            began = clock()
            lost = None
            try:
                runner.run(None if end is None else max(0.0, end - clock()))
            except LinkLostError as exc:
                lost = str(exc)
            served.add(sim, began=began - t0, ended=clock() - t0, link_lost=lost)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        rt.close()
        adapter.close()
        if writer is not None:
            writer.close()
    problem = None
    if not served.sessions:
        waited = (args.accept_timeout if args.duration is None
                  else min(args.accept_timeout, args.duration))
        problem = (f"no host connected within {waited:g} s" if not interrupted
                   else "interrupted before any host")
    out = sim_summary(sim or eyeq, served.sessions, elapsed=clock() - t0,
                      wall=clock() - t0, cpu=time.process_time() - cpu0,
                      interrupted=interrupted, address=address, scheduling=scheduling,
                      problem=problem)
    print_summary(out, args.json)
    return 0 if out["ok"] else 1


def _reopen(url: str, until: float) -> Any:
    """Open ``url`` again, retrying until ``until`` (monotonic); None if it never came back."""
    from eyeq_spi.errors import AdapterError
    from eyeq_spi.phy.base import open_url

    while time.monotonic() < until:
        try:
            return open_url(url)
        except AdapterError:
            time.sleep(min(0.2, max(0.0, until - time.monotonic())))
    return None


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
    from eyeq_spi.errors import LinkLostError
    from eyeq_spi.host.host import HostEmulator
    from eyeq_spi.host.machine import HostState
    from eyeq_spi.phy.address import parse_connect
    from eyeq_spi.report import host_summary
    from eyeq_spi.runner.realtime import RealTimeRunner
    from eyeq_spi.runner.sched import realtime

    host_cfg, nvm, scenario = host_parts(args)
    host = HostEmulator(host_cfg, nvm=nvm, scenario=scenario, keep_rx_times=False)
    host.warm_up()
    gc.collect()
    # --reconnect: the EyeQ may not be there yet (a sim still starting, a camera powering up)
    adapter: Any = ((_reopen(args.port, time.monotonic() + args.duration) if args.reconnect
                     else None) or _open_or_say(args))
    _on_sigterm()
    writer = capture_writer(args)
    runner = RealTimeRunner(host, adapter)
    runner.tap = _realtime_tap(writer, runner.clock(), "h2e", "e2h")
    from eyeq_spi.can.sinks import attach_from_args

    can_out = attach_from_args(args, host, runner)  # --can-out: the CAN gateway
    gc.freeze()
    view = LiveView(sys.stderr.isatty() and not args.json)
    start, cpu0 = runner.clock(), time.process_time()
    end = start + args.duration
    host.start(start)
    running_since: float | None = None
    left: list[float] = []
    link_lost: str | None = None
    connections = 1
    interrupted = False
    rt = contextlib.ExitStack()  # real-time scheduling for the live run only
    scheduling = rt.enter_context(realtime(args.rt_priority))
    try:
        while runner.clock() < end:
            try:
                runner.step()
            except LinkLostError as exc:
                link_lost = str(exc)
                adapter.close()
                if not args.reconnect:
                    break
                adapter = _reopen(args.port, end)
                if adapter is None:
                    break
                link_lost = None
                connections += 1
                runner.adapter = adapter
                host.link_restarted(runner.clock())
                running_since, left = None, []  # judged again on the new connection
                continue
            now = runner.clock()
            view.update(host, now - start)
            if host.state is HostState.RUNNING_VISION and running_since is None:
                running_since = now - start
            elif host.state is not HostState.RUNNING_VISION and running_since is not None:
                left.append(now - start)
                running_since = None
            if host.state in (HostState.FAILED, HostState.BOOT_FAILED):
                break
            if args.exit_when_running and running_since is not None:
                break
    except KeyboardInterrupt:
        interrupted = True
    finally:
        rt.close()
        if adapter is not None:
            adapter.close()
        nvm.save()
        if writer is not None:
            writer.close()
        if can_out is not None:
            can_out.close()
    now = runner.clock()
    out = host_summary(host, side="host", elapsed=now - start, wall=now - start,
                       cpu=time.process_time() - cpu0, running_since=running_since,
                       left_running=left, link_lost=link_lost, connections=connections,
                       interrupted=interrupted, t0=start,
                       address=parse_connect(args.port, check_path=False).display,
                       scheduling=scheduling)
    if can_out is not None:
        out["can"] = can_out.summary()
    print_summary(out, args.json)
    return 0 if out["ok"] else 1
