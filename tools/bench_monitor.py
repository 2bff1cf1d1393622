#!/usr/bin/env python3
"""What the live monitor costs the emulator: each figure with and without the monitor.

0. One redraw (snapshot, screen, ANSI write of a 150x60 screen through rich ``Live``): CPU ms,
   against an in-run baseline that draws the same snapshot as rich ``Table``s (what the monitor
   did before it drew fixed-column lines of Text).
1. ``demo --virtual-time``: CPU seconds per simulated second (host + EyeQ), baseline = the
   emulation alone, in slices as ``eyeq-spi demo`` runs it.
2. ``demo`` in real time: how far virtual time trails the wall clock (worst lag), the obstacle
   message rate and the link errors, and the redraw rate the monitor achieved.
3. ``host`` against ``eyeq-spi sim`` over TCP (two processes, real link timers): the host's
   link error counters (sendFailed, CRC, sequence) and MESP timeouts, the obstacle rate, and
   the redraw rate.

With the monitor, screens are written as to a 150x60 terminal (ANSI, rich ``Live``) into
/dev/null. Each case runs ``--runs`` times; figures are median and spread (min..max) and the
ratio of the medians with/without. Run from the repository root: ``python tools/bench_monitor.py``.
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from eyeq_spi.emulator import build  # noqa: E402
from eyeq_spi.monitor.app import run  # noqa: E402
from eyeq_spi.monitor.sources import DemoSource, HostSource  # noqa: E402

OBST = "EYEQ_VIS_OBSTACLES_MSG"


def _console() -> Any:
    from rich.console import Console

    sink = open(os.devnull, "w")  # noqa: SIM115 - lives as long as the console
    return Console(file=sink, force_terminal=True, width=150, height=60,
                   color_system="truecolor")


def _fmt(xs: list[float], unit: str = "", spec: str = ".3f") -> str:
    return (f"{statistics.median(xs):{spec}}{unit} "
            f"({min(xs):{spec}}..{max(xs):{spec}})")


def _ratio(a: list[float], b: list[float]) -> str:
    base = statistics.median(b)
    return f"x{statistics.median(a) / base:.2f}" if base else "-"


def _table_screen(snap: Any) -> Any:
    """The baseline: the same snapshot as rich Tables with fixed column widths."""
    from rich import box
    from rich.console import Group
    from rich.table import Table

    from eyeq_spi.monitor import view

    def table(title: str, cols: list[Any], rows: list[list[str]]) -> Any:
        t = Table(title=title, title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False)
        for head, width, just in cols:
            t.add_column(head, width=width + 1, justify=just, no_wrap=True, overflow="ellipsis")
        for r in rows:
            t.add_row(*r)
        return t

    def pair(a: Any, b: Any) -> Any:
        g = Table.grid(padding=(0, 3))
        g.add_row(a, b)
        return g

    rates = [[r.name, str(r.count), f"{r.hz or 0:5.1f}", f"{r.nominal_hz or 0:g}", r.status]
             for r in snap.rates]
    link = [[k, str(v)] for k, v in {**snap.link, **snap.errors}.items()]
    objs = [[str(o.id), o.cls_name, f"{o.long:.1f}", f"{o.lat:.1f}", f"{o.v_long:.1f}",
             f"{o.v_lat:.1f}", f"{o.ttc or 0:.1f}"] for o in snap.scene.objects]
    road = [[ln.name, ln.kind, f"{ln.coeffs[0]:.2f}", f"{ln.start:.0f}"]
            for ln in snap.scene.lines]
    trans = [[f"{t:.3f}", a, e, b] for t, a, e, b in snap.transitions]
    return Group(snap.source,
                 pair(table("rates", view.RATE_COLS, rates), table("link", view.LINK_COLS, link)),
                 pair(table("objects", view.OBJECT_COLS, objs),
                      table("road", view.ROAD_COLS, road)),
                 table("transitions", view.TRANSITION_COLS, trans))


def redraw(n: int) -> tuple[float, float]:
    """CPU ms per redraw: the monitor's screen and the rich-Table baseline, same snapshots."""
    from rich.live import Live

    from eyeq_spi.monitor.view import render

    emu = build(keep_rx_times=False)
    src = DemoSource(emu, 1e9, realtime=False)
    emu.run_for(2.0)
    out = []
    for draw in (render, _table_screen):
        live = Live(console=_console(), auto_refresh=False, vertical_overflow="crop",
                    redirect_stdout=False, redirect_stderr=False)
        live.start()
        cpu = 0.0
        for _ in range(n):
            emu.run_for(0.05)
            c0 = time.process_time()
            live.update(draw(src.snapshot()), refresh=True)
            cpu += time.process_time() - c0
        live.stop()
        out.append(cpu / n * 1e3)
    return out[0], out[1]


def virtual(duration: float) -> tuple[float, float, float]:
    """CPU s per simulated s without and with the monitor, and CPU ms per redraw."""
    emu = build(keep_rx_times=False)
    c0 = time.process_time()
    while emu.runner.now < duration - 1e-9:
        emu.run_for(0.25)
    base = (time.process_time() - c0) / duration
    emu = build(keep_rx_times=False)
    c0 = time.process_time()
    st = run(DemoSource(emu, duration, realtime=False), console=_console())
    per_draw = st.draw_cpu_s / st.redraws * 1e3
    return base, (time.process_time() - c0) / duration, per_draw


def realtime(duration: float, monitor: bool) -> dict[str, float]:
    emu = build(keep_rx_times=False)
    lag = 0.0
    redraws = 0
    w0, c0 = time.perf_counter(), time.process_time()
    if monitor:
        src = DemoSource(emu, duration, realtime=True)

        def on_draw(_s: Any) -> None:
            nonlocal lag
            lag = max(lag, (time.perf_counter() - src.start) - emu.runner.now)

        redraws = run(src, console=_console(), on_draw=on_draw).redraws
    else:
        t = 0.0
        while t < duration:  # exactly run_demo's loop
            step = min(0.25, duration - t)
            emu.run_for(step, realtime=True)
            t += step
            lag = max(lag, (time.perf_counter() - w0) - emu.runner.now)
    wall = time.perf_counter() - w0
    cpu = time.process_time() - c0
    link = emu.host.conn.link.counters.seed_view()
    return {"lag_ms": lag * 1e3, "cpu_per_sim_s": cpu / duration,
            "obst_hz": emu.host.counters.received[OBST] / duration,
            "link_errors": float(sum(link.values())), "redraw_hz": redraws / wall,
            "wall_s": wall}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def host_tcp(duration: float, monitor: bool, ack_ms: float | None) -> dict[str, float]:
    from eyeq_spi.host.host import HostConfig, HostEmulator
    from eyeq_spi.phy.base import open_url
    from eyeq_spi.runner.realtime import RealTimeRunner

    port = _free_port()
    timing = [] if ack_ms is None else ["--ack-timeout", str(ack_ms), "--transmit-timeout",
                                        str(2.5 * ack_ms)]
    sim = subprocess.Popen([sys.executable, "-m", "eyeq_spi.cli", "sim", "--listen",
                            f"tcp://127.0.0.1:{port}", "--duration", str(duration + 5), *timing],
                           cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                           text=True)
    try:
        assert sim.stderr is not None
        line = sim.stderr.readline()  # LISTEN URL, on stderr
        m = re.search(r"^LISTEN (\S+)", line)
        if not m:
            raise SystemExit(f"sim did not say where it listens: {line!r}")
        cfg = HostConfig() if ack_ms is None else HostConfig(
            ack_timeout=ack_ms / 1e3, transmit_timeout=2.5 * ack_ms / 1e3)
        host = HostEmulator(cfg, keep_rx_times=False)
        adapter = open_url(m.group(1))
        runner = RealTimeRunner(host, adapter, max_wait=0.01)
        src = HostSource(host, runner, duration, on_close=adapter.close)
        w0 = time.perf_counter()
        if monitor:
            redraws = run(src, console=_console()).redraws
        else:
            while not src.done:
                src.advance(time.perf_counter() + 0.2)
            src.close()
            redraws = 0
        wall = time.perf_counter() - w0
    finally:
        sim.kill()
        sim.wait(10)
    link = host.conn.link.counters.seed_view()
    # the rate while in Running Vision (bring-up over real link timers takes a while)
    since = [t.time for t in host.transitions if t.dst.value == "RUNNING_VISION"]
    running = src.now - (since[0] - src.start) if since else 0.0
    return {"obst_hz": host.counters.received[OBST] / running if running > 0 else 0.0,
            "link_errors": float(sum(link.values())),
            "mesp_timeouts": float(host.mesp.counters.timeouts), "redraw_hz": redraws / wall,
            "state_ok": float(host.state.value == "RUNNING_VISION")}


def _pairs(fn: Callable[[bool], dict[str, float]], runs: int) -> tuple[dict[str, list[float]],
                                                                         dict[str, list[float]]]:
    without: dict[str, list[float]] = {}
    with_: dict[str, list[float]] = {}
    for _ in range(runs):
        for flag, out in ((False, without), (True, with_)):
            for k, v in fn(flag).items():
                out.setdefault(k, []).append(v)
    return without, with_


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--duration", type=float, default=5.0, help="seconds per real-time run")
    ap.add_argument("--virtual", type=float, default=20.0, help="simulated seconds per run")
    ap.add_argument("--ack-timeout", type=float, metavar="MS",
                    help="host/sim link ackTimeout (default: the seed's 10 ms; transmitTimeout "
                    "follows at 2.5x) for an overloaded machine")
    ap.add_argument("--only", choices=("redraw", "virtual", "realtime", "host"),
                    help="one case only")
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")

    if args.only in (None, "redraw"):
        _redraw(args)
    if args.only in (None, "virtual"):
        _virtual(args)
    if args.only in (None, "realtime"):
        _realtime(args)
    if args.only in (None, "host"):
        _host(args)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")
    return 0


def _redraw(args: argparse.Namespace) -> None:
    mine, base = [], []
    for _ in range(args.runs):
        a, b = redraw(60)
        mine.append(a)
        base.append(b)
    print(f"one redraw, CPU: {_fmt(mine, ' ms', '.2f')}; rich-Table baseline "
          f"{_fmt(base, ' ms', '.2f')} ({_ratio(mine, base)})")


def _virtual(args: argparse.Namespace) -> None:
    base, mon, draw = [], [], []
    for _ in range(args.runs):
        a, b, c = virtual(args.virtual)
        base.append(a)
        mon.append(b)
        draw.append(c)
    print(f"demo --virtual-time, CPU s per simulated s: without {_fmt(base)}, "
          f"with monitor {_fmt(mon)} ({_ratio(mon, base)}); CPU per redraw "
          f"{_fmt(draw, ' ms', '.1f')}")


def _realtime(args: argparse.Namespace) -> None:
    wo, wi = _pairs(lambda m: realtime(args.duration, m), args.runs)
    print(f"demo real time, {args.duration:g} s:")
    for k in ("lag_ms", "cpu_per_sim_s", "obst_hz", "link_errors"):
        print(f"  {k:12s} without {_fmt(wo[k])}  with {_fmt(wi[k])}  ({_ratio(wi[k], wo[k])})")
    print(f"  redraws/s with monitor {_fmt(wi['redraw_hz'], spec='.2f')}")


def _host(args: argparse.Namespace) -> None:
    wo, wi = _pairs(lambda m: host_tcp(args.duration, m, args.ack_timeout), args.runs)
    ack = "seed timers" if args.ack_timeout is None else f"ackTimeout {args.ack_timeout:g} ms"
    print(f"host against sim over TCP, {args.duration:g} s, {ack}:")
    for k in ("obst_hz", "link_errors", "mesp_timeouts", "state_ok"):
        print(f"  {k:12s} without {_fmt(wo[k])}  with {_fmt(wi[k])}  ({_ratio(wi[k], wo[k])})")
    print(f"  redraws/s with monitor {_fmt(wi['redraw_hz'], spec='.2f')}")


if __name__ == "__main__":
    sys.exit(main())
