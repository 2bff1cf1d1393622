#!/usr/bin/env python3
"""CAN gateway and CAN log decoder figures.

1. Gateway cost: the in-process emulator at full load (15 objects, 20 signs, 15 light spots) for
   ``--seconds`` of virtual time, CPU seconds without a gateway (the in-run baseline), with the
   extlog2 gateway and with the me8 gateway (frames to a list: no I/O).
2. Decoder throughput: a BLF written by the gateway, read by python-can's reader alone (the
   baseline) and read and decoded by ``CanDecoder``, in frames/s.
3. ``can decode`` on a camera-shaped BLF (``tests/camera_can.py``, about 100 k frames on four
   channels): CPU of ``--stats`` and ``--json`` (with and without ``--channel``) as ratios to
   python-can's reader alone on the same file, measured right before each run.

Each figure is the median of ``--repeat`` runs with its spread (min..max) and its ratio to the
baseline of the same run. ``python tools/bench_can.py [--seconds 10] [--repeat 3]
[--only-decode]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from eyeq_spi.can.decode import CanDecoder, read_log
from eyeq_spi.can.gateway import CanFrame, CanGateway, GatewayNode
from eyeq_spi.can.sinks import attach
from eyeq_spi.emulator import build
from eyeq_spi.sim.config import SimConfig

FULL = SimConfig(objects=15, signs=20, light_spots=15)


def emulate(seconds: float, proto: str | None) -> tuple[float, int]:
    emu = build(sim_config=FULL, keep_rx_times=False)
    frames: list[CanFrame] = []
    if proto is not None:
        gw = CanGateway(proto, vehicle=emu.host.scenario.signals)
        emu.host.subscribe(gw.on_message)
        node = GatewayNode(emu.host, gw, frames.append)
        emu.runner.nodes = [(node if n is emu.host else n, a) for n, a in emu.runner.nodes]
    c0 = time.process_time()
    emu.run_for(seconds)
    return time.process_time() - c0, len(frames)


def summary(values: list[float]) -> str:
    return f"{statistics.median(values):.3f} ({min(values):.3f}..{max(values):.3f})"


def cpu(fn: Any) -> float:
    c0 = time.process_time()
    fn()
    return time.process_time() - c0


def gateway_log_decode(args: argparse.Namespace) -> None:
    """Frames/s of a gateway-written BLF: python-can alone, and read + decode per frame."""
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "bench.blf"
        emu = build(sim_config=FULL, keep_rx_times=False)
        out = attach(emu.host, emu.runner, target=str(log), protocol="extlog2")
        emu.run_for(max(args.seconds, 10.0))
        out.close()
        read_s: list[float] = []
        decode_s: list[float] = []
        n = 0
        dec = CanDecoder("extlog2")
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            n = sum(1 for _ in read_log(str(log)))
            read_s.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            sink: Any = None
            for i, m in enumerate(read_log(str(log))):
                sink = dec.decode(m, i)
            decode_s.append(time.perf_counter() - t0)
            del sink
        rate_read = [n / s for s in read_s]
        rate_dec = [n / s for s in decode_s]
        print(f"decoder, gateway log: {n} frames ({log.stat().st_size // 1024} KiB BLF), "
              f"frames/s: median (min..max)")
        print(f"  python-can read only {summary(rate_read)} (baseline)")
        print(f"  read + decode        {summary(rate_dec)}, "
              f"{statistics.median(rate_dec) / statistics.median(rate_read):.2f}x baseline")


def camera_log_decode(args: argparse.Namespace) -> None:
    """``can decode`` CPU on a camera-shaped log (tests/camera_can.py: four channels, the
    camera's frames on one), as ratios to python-can's reader alone on the same file, measured
    in the same run right before each figure."""
    import can

    from eyeq_spi.cli import main as cli
    from tests import camera_can

    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "camera.blf"
        info = camera_can.write(log, seconds=args.log_seconds)
        path, ch = str(log), camera_can.camera_channel(".blf")
        runs = {"--stats": ["--stats"], "--stats --channel": ["--stats", "--channel", ch],
                "--json": ["--json"], "--json --channel": ["--json", "--channel", ch]}
        ratios: dict[str, list[float]] = {k: [] for k in runs}
        base_s: list[float] = []
        real = sys.stdout
        with open(os.devnull, "w") as devnull:
            sys.stdout = devnull
            try:
                cli(["can", "decode", path, "--stats"])  # warm: imports, spec, decoders
                for _ in range(args.repeat):
                    for key, extra in runs.items():
                        base = cpu(lambda: sum(1 for _ in can.LogReader(path)))
                        base_s.append(base)
                        ratios[key].append(cpu(lambda e=extra: cli(["can", "decode", path,
                                                                     *e])) / base)
            finally:
                sys.stdout = real
        print(f"can decode, camera-shaped log: {info.frames} frames "
              f"({log.stat().st_size // 1024} KiB BLF, {info.per_channel.get(1, 0)} on the "
              f"camera's channel); python-can reader alone {summary(base_s)} CPU s")
        print("  CPU ratio to python-can's reader alone: median (min..max)")
        for key, vals in ratios.items():
            print(f"  can decode {key:18s} {summary(vals)}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--log-seconds", type=float, default=150.0,
                    help="length of the camera-shaped log (default 150 s, about 100 k frames)")
    ap.add_argument("--only-decode", action="store_true",
                    help="only the camera-log decoder figures (no emulator, no gateway)")
    ap.add_argument("--skip-gateway-log", action="store_true",
                    help="skip the decoder figure on a gateway-written log")
    args = ap.parse_args()
    if args.only_decode:
        camera_log_decode(args)
        return 0
    rows: dict[str, list[float]] = {"none": [], "extlog2": [], "me8": []}
    nframes: dict[str, int] = {}
    for _ in range(args.repeat):
        for key in rows:
            cpu, n = emulate(args.seconds, None if key == "none" else key)
            rows[key].append(cpu)
            nframes[key] = n
    base = statistics.median(rows["none"])
    print(f"emulator at full load, {args.seconds:g} s virtual, CPU s: median (min..max)")
    for key, vals in rows.items():
        extra = (f", {nframes[key] / args.seconds:.0f} frames/s, "
                 f"{statistics.median(vals) / base:.2f}x baseline") if key != "none" else \
            " (baseline)"
        print(f"  gateway {key:8s} {summary(vals)}{extra}")

    if not args.skip_gateway_log:
        gateway_log_decode(args)
    camera_log_decode(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
