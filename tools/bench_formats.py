#!/usr/bin/env python3
"""Read speeds of every capture format dissect reads, in frames (transfers) per second, beside
an in-run baseline: reading the same transfers from our own pcapng captures.

A demo capture (virtual time) is converted in memory to raw, hex, pcapng, Saleae Logic 2,
Saleae Logic 1.x and VCD (our layout, one change per line, and sigrok's/PulseView's, a time and
its changes on one line); each is read ``--repeat`` times through ``open_transfers`` (reading
only), and once more through the dissector engine (reading + decoding). Export speeds (VCD,
MDF4, MCAP writers) close the table.
Figures: median and spread (min-max) of the repeats, and the ratio to the baseline's median.

    python tools/bench_formats.py [--duration 2] [--repeat 5]
"""

from __future__ import annotations

import argparse
import binascii
import contextlib
import io
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from eyeq_spi.capture.pcapng_io import Transfer, read_pcapng
from eyeq_spi.dissect.engine import Dissector
from eyeq_spi.io.plain import open_transfers
from eyeq_spi.logic.vcd_write import write_vcd


def _demo(duration: float, path: Path) -> list[Transfer]:

    from eyeq_spi.cli import main

    with contextlib.redirect_stdout(io.StringIO()):
        rc = main(["demo", "--virtual-time", "--duration", str(duration), "--capture",
                   str(path), "--json"])
    if rc != 0:
        raise SystemExit("demo failed")
    with path.open("rb") as fh:
        return list(read_pcapng(fh))


def _formats(recs: list[Transfer], pcapng: bytes) -> dict[str, tuple[bytes, dict[str, str]]]:
    raw = b"".join(r.data for r in recs if r.direction == "e2h" and len(r.data) == 128)
    hex_ = "".join(f"{r.time:.6f} {r.direction} {binascii.hexlify(r.data).decode()}\n"
                   for r in recs).encode()
    s2 = ['name,type,start_time,duration,"mosi","miso"']
    for r in recs:
        t = r.time or 0.0
        s2.append(f'"{r.direction}","enable",{t!r},2e-08,,')
        s2 += [f'"{r.direction}","result",{t + i * 8e-7:.9f},8e-07,0x{b:02X},0xFF'
               for i, b in enumerate(r.data)]
        s2.append(f'"{r.direction}","disable",{t + 1.1e-4!r},2e-08,,')
    s1 = ["Time [s],Packet ID,MOSI,MISO"]
    for pid, r in enumerate(x for x in recs if x.direction == "e2h"):
        t = r.time or 0.0
        s1 += [f"{t + i * 8e-7:.9f},{pid},0x{b:02X},0x00" for i, b in enumerate(r.data)]
    vcd = io.StringIO()
    write_vcd(recs, vcd)
    return {
        "raw": (raw, {"direction": "e2h"}), "hex": (hex_, {}), "pcapng": (pcapng, {}),
        "saleae2": ("\n".join(s2).encode() + b"\n", {}),
        "saleae1": ("\n".join(s1).encode() + b"\n", {"direction": "e2h"}),
        "vcd": (vcd.getvalue().encode(), {}),
        "vcd-sigrok": (_sigrok_layout(vcd.getvalue()).encode(), {"format": "vcd"}),
    }


def _sigrok_layout(text: str) -> str:
    """Our VCD with each time and its changes on one line, as sigrok and PulseView write it."""
    head, body = text.split("$enddefinitions $end\n", 1)
    out: list[str] = []
    for line in body.split("\n"):
        if out and not line.startswith(("#", "$")) and not out[-1].startswith("$"):
            out[-1] += " " + line
        else:
            out.append(line)
    return head + "$enddefinitions $end\n" + "\n".join(out)


def _time(fn: Callable[[], int], repeat: int) -> tuple[list[float], int]:
    times, n = [], 0
    for _ in range(repeat):
        t0 = time.perf_counter()
        n = fn()
        times.append(time.perf_counter() - t0)
    return times, n


def _read(data: bytes, fmt: str, kw: dict[str, str]) -> int:
    _, it = open_transfers(io.BytesIO(data), kw.get("format", fmt), kw.get("direction"))
    return sum(1 for _ in it)


def _dissect(data: bytes, fmt: str, kw: dict[str, str]) -> int:
    _, it = open_transfers(io.BytesIO(data), kw.get("format", fmt), kw.get("direction"))
    dis = Dissector()
    n = 0
    for rec in it:
        n += 1
        for _ in dis.feed(rec):
            pass
    return n


def _row(name: str, times: list[float], n: int, base: float | None) -> str:
    rates = sorted(n / t for t in times)
    med = statistics.median(rates)
    ratio = "" if base is None else f"{med / base:8.3f}"
    return (f"{name:28s} {n:7d} {med:12,.0f} {rates[0]:10,.0f}-{rates[-1]:<10,.0f} "
            f"{ratio}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=2.0, help="seconds of demo (default 2)")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        cap = Path(d) / "demo.pcapng"
        recs = _demo(args.duration, cap)
        formats = _formats(recs, cap.read_bytes())
        print(f"{len(recs)} transfers from {args.duration} s of demo; sizes: " + ", ".join(
            f"{k} {len(v[0]) / 1e6:.1f} MB" for k, v in formats.items()))
        print(f"{'frames/s':28s} {'frames':>7s} {'median':>12s} {'spread (min-max)':^21s} "
              "ratio to pcapng read")
        base_times, base_n = _time(lambda: _read(formats["pcapng"][0], "pcapng", {}),
                                   args.repeat)
        base = statistics.median(base_n / t for t in base_times)
        for fmt, (data, kw) in formats.items():
            times, n = _time(lambda data=data, fmt=fmt, kw=kw: _read(data, fmt, kw),  # type: ignore[misc]
                             args.repeat)
            print(_row(f"read {fmt}", times, n, base))
        for fmt, (data, kw) in formats.items():
            times, n = _time(lambda data=data, fmt=fmt, kw=kw: _dissect(data, fmt, kw),  # type: ignore[misc]
                             max(1, args.repeat // 2))
            print(_row(f"read+dissect {fmt}", times, n, base))
        from eyeq_spi.interop.export import export

        for out in ("vcd", "mdf", "mcap"):
            target = str(Path(d) / f"out.{out}")
            times, n = _time(lambda out=out, target=target: export(  # type: ignore[misc]
                iter(recs), source="bench", **{out: target})["transfers"],
                max(1, args.repeat // 2))
            print(_row(f"export {out}", times, n, base))
    return 0


if __name__ == "__main__":
    sys.exit(main())
