"""``eyeq-spi demo``, ``eyeq-spi sim`` and ``eyeq-spi host``: shared fault and scenario options,
and the three ways of running the emulator."""

from __future__ import annotations

import argparse
import gc
import json
import sys
import time
from collections import Counter
from typing import Any

from eyeq_spi.errors import UsageError


def add_shared_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scenario")
    g.add_argument("--seed", type=int, default=1, help="random seed of the scene (default 1)")
    g.add_argument("--sw", help="SW version both sides speak, e.g. 9.0 or 8.1 (default newest)")
    g.add_argument("--speed", type=float, default=25.0, help="constant drive speed, m/s")
    g.add_argument("--scenario", metavar="CSV", help="vehicle signals from a CSV (time,...)")
    g.add_argument("--objects", type=int, default=8, help="tracked objects, 0..15 (default 8)")
    g.add_argument("--signs", type=int, default=4, help="traffic signs, 0..20 (default 4)")
    g.add_argument("--light-spots", type=int, default=4, help="light spots, 0..15 (default 4)")
    g.add_argument("--camera-only-aeb", action="store_true", help="send IPB/PCW (0x78/0x79)")
    g.add_argument("--ack-timeout", type=float, metavar="MS",
                   help="link ackTimeout in ms (default 10, seed §6); raise it for slow bridges")
    g.add_argument("--transmit-timeout", type=float, metavar="MS",
                   help="link transmitTimeout in ms (default 25, seed §6)")
    g.add_argument("--capture", metavar="FILE.pcapng",
                   help="write every SPI transfer of both channels to a pcapng capture")
    f = p.add_argument_group("faults (simulated EyeQ)")
    f.add_argument("--boot-fail", type=int, default=0, metavar="N",
                   help="the first N boots report failing test bits")
    f.add_argument("--boot-test-bits", type=lambda s: int(s, 0), default=0x0002,
                   metavar="BITS", help="TestResults bits of a failing boot (default 0x0002)")
    f.add_argument("--corrupt-eeprom", action="store_true", help="EEPROM CRC does not match")
    f.add_argument("--fatal", type=int, metavar="CODE", help="force Fatal_Error CODE in 0x41")
    f.add_argument("--reply-delay", type=float, default=0.0, metavar="S",
                   help="delay every MESP reply by S seconds")
    f.add_argument("--drop-reply", action="append", default=[], metavar="FUNCTION[:N]",
                   help="drop the first N (default 1) replies to a MESP function")
    f.add_argument("--reset-at", type=float, metavar="T", help="the EyeQ resets at time T")
    f.add_argument("--stop-dasp", action="append", default=[], metavar="MESSAGE@T",
                   help="stop sending a DASP message at time T")


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
    for item in args.drop_reply:
        fn, _, n = item.partition(":")
        try:
            drops[fn] = int(n or 1)
        except ValueError:
            raise UsageError(f"--drop-reply {item!r}: N must be an integer") from None
    stops: dict[str, float] = {}
    for item in args.stop_dasp:
        name, sep, t = item.partition("@")
        try:
            stops[name] = float(t) if sep else 0.0
        except ValueError:
            raise UsageError(f"--stop-dasp {item!r}: T must be seconds") from None
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


class LiveView:
    """On a TTY: state transitions as they happen and message rates once a second."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.shown = 0
        self.last_counts: Counter[str] = Counter()
        self.last_t = 0.0

    def update(self, host: Any, now: float) -> None:
        if not self.enabled:
            return
        for t in host.transitions[self.shown:]:
            print(f"[{t.time:8.3f}] {t.src.value:>18s} --{t.event.value}--> {t.dst.value}",
                  file=sys.stderr)
        self.shown = len(host.transitions)
        if now - self.last_t >= 1.0:
            counts = Counter(host.counters.received)
            dt = now - self.last_t
            rates = {k: (v - self.last_counts.get(k, 0)) / dt for k, v in counts.items()}
            line = "  ".join(f"{k.replace('EYEQ_', '').replace('_MSG', '')}:{r:4.1f}"
                             for k, r in sorted(rates.items()) if r > 0)
            print(f"[{now:8.3f}] {host.state.value:14s} Hz {line}", file=sys.stderr)
            self.last_counts, self.last_t = counts, now


def _capture(args: argparse.Namespace) -> Any:
    if not args.capture:
        return None
    from eyeq_spi.capture.pcapng_io import CaptureWriter

    return CaptureWriter(args.capture)


def _realtime_tap(writer: Any, start: float, tx: str, rx: str) -> Any:
    if writer is None:
        return None

    def tap(kind: str, t: float, transfer: bytes) -> None:
        writer.write(tx if kind == "tx" else rx, t - start, transfer)

    return tap


def run_demo(args: argparse.Namespace) -> int:
    from eyeq_spi.emulator import build, summary
    from eyeq_spi.host.machine import HostState

    if args.duration <= 0:
        raise UsageError("--duration must be positive")
    host_cfg, nvm, scenario = host_parts(args)
    writer = _capture(args)
    tap = None
    if writer is not None:
        def tap(node: int, t: float, transfer: bytes) -> None:
            writer.write("h2e" if node == 0 else "e2h", t, transfer)
    emu = build(sim_config=sim_config(args), host_config=host_cfg, nvm=nvm, scenario=scenario,
                keep_rx_times=False, tap=tap)
    view = LiveView(sys.stderr.isatty() and not args.json)
    t = 0.0
    while t < args.duration:
        step = min(0.25, args.duration - t)
        emu.run_for(step, realtime=not args.virtual_time)
        t += step
        view.update(emu.host, emu.runner.now)
    if writer is not None:
        writer.close()
    out = summary(emu)
    held = emu.host.state is HostState.RUNNING_VISION and emu.running_since is not None
    out["ok"] = held and not emu.left_running
    if args.json:
        print(json.dumps(out, sort_keys=True))
    else:
        print(f"state {out['state']} after {out['virtual_s']:.2f} s "
              f"({'virtual' if args.virtual_time else 'real'} time, wall {out['wall_s']:.2f} s)")
        for name, n in sorted(out["messages"].items()):
            print(f"  {name:34s} {n:7d}")
        print(f"  link {out['link']}")
        print(f"  e2e errors {out['e2e_errors']}, counter gaps {out['dasp_counter_gaps']}, "
              f"stale {out['stale_streams'] or 'none'}")
        if out["problem"]:
            print(f"  problem: {out['problem']}")
    return 0 if out["ok"] else 1


def run_sim(args: argparse.Namespace) -> int:
    from eyeq_spi.phy.base import open_url
    from eyeq_spi.runner.realtime import RealTimeRunner
    from eyeq_spi.sim.eyeq import SimulatedEyeQ

    if bool(args.listen) == bool(args.pty):
        raise UsageError("give exactly one of --listen tcp://HOST:PORT or --pty")
    sim = SimulatedEyeQ(sim_config(args))
    if args.pty:
        from eyeq_spi.phy.pty import PtyAdapter

        adapter: Any = PtyAdapter()
        print(f"PTY {adapter.path}", flush=True)
        if not adapter.accept(args.accept_timeout):
            raise UsageError(f"nobody opened {adapter.path} within {args.accept_timeout} s")
    else:
        url = args.listen
        if not url.startswith("tcp://"):
            raise UsageError("--listen takes tcp://HOST:PORT")
        adapter = open_url("listen://" + url[len("tcp://"):], timeout=args.accept_timeout)
        print(f"LISTEN {adapter.url}", flush=True)
        if not adapter.accept(args.accept_timeout):
            raise UsageError(f"no host connected within {args.accept_timeout} s")
    writer = _capture(args)
    runner = RealTimeRunner(sim, adapter)
    runner.tap = _realtime_tap(writer, runner.clock(), "e2h", "h2e")
    gc.freeze()  # the catalogue and layouts live forever: keep collections short
    sim.power_up(runner.clock())
    try:
        runner.run(args.duration)
    finally:
        adapter.close()
        if writer is not None:
            writer.close()
    if args.json:
        print(json.dumps({"boots": sim.counters.boots, "sent": dict(sim.counters.sent),
                          "main_state": sim.main_state}, sort_keys=True))
    return 0


def run_host(args: argparse.Namespace) -> int:
    from eyeq_spi.host.host import HostEmulator
    from eyeq_spi.host.machine import HostState
    from eyeq_spi.phy.base import open_url
    from eyeq_spi.runner.realtime import RealTimeRunner

    host_cfg, nvm, scenario = host_parts(args)
    host = HostEmulator(host_cfg, nvm=nvm, scenario=scenario, keep_rx_times=False)
    adapter = open_url(args.port)
    writer = _capture(args)
    runner = RealTimeRunner(host, adapter)
    runner.tap = _realtime_tap(writer, runner.clock(), "h2e", "e2h")
    gc.freeze()
    view = LiveView(sys.stderr.isatty() and not args.json)
    host.start(runner.clock())
    start = runner.clock()
    running_since: float | None = None
    left = False
    try:
        while runner.clock() - start < args.duration:
            runner.step()
            now = runner.clock()
            view.update(host, now - start)
            if host.state is HostState.RUNNING_VISION and running_since is None:
                running_since = now
            elif host.state is not HostState.RUNNING_VISION and running_since is not None:
                left = True
            if host.state in (HostState.FAILED, HostState.BOOT_FAILED):
                break
            if args.exit_when_running and running_since is not None:
                break
    finally:
        adapter.close()
        nvm.save()
        if writer is not None:
            writer.close()
        time.sleep(0)  # let the OS flush the socket
    received = dict(host.counters.received)
    out: dict[str, Any] = {"state": host.state.value, "messages": received,
           "link": host.conn.link.counters.seed_view(), "e2e_errors": host.counters.e2e_errors,
           "problem": host.problem, "versions": host.versions}
    ok = running_since is not None and not left
    out["ok"] = ok
    if args.json:
        print(json.dumps(out, sort_keys=True))
    else:
        print(f"state {out['state']}; messages {sum(received.values())}; "
              f"problem {out['problem']}")
    return 0 if ok else 1
