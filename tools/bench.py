#!/usr/bin/env python3
"""Benchmarks (figures go in the closing note and README, never in timed unit tests).

- frame codec: encode and decode frames/s;
- EYEQ_VIS_OBSTACLES_MSG with 15 objects: µs per decode with the specs-built construct codec,
  beside a hand-written ``struct.unpack_from`` decoder of the same SW9 layout in the same run;
- the emulator: host + simulated EyeQ at full load in virtual time, wall and CPU per
  simulated second, the host alone, median and spread, as ratios to an in-run CRC baseline.
"""

from __future__ import annotations

import argparse
import binascii
import json
import math
import statistics
import struct
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for tests.strategies

from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.link.frame import FrameCodec


def rate(fn: Callable[[], Any], seconds: float = 1.0) -> float:
    """Calls per second, measured for about ``seconds``."""
    n, t0 = 0, time.perf_counter()
    batch = 1
    while True:
        for _ in range(batch):
            fn()
        n += batch
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return n / dt
        batch = min(batch * 2, 10_000)


def frame_bench(seconds: float) -> dict[str, float]:
    c = FrameCodec()
    wire = c.data_frame(17, 42, bytes(range(122)))
    return {
        "frame_encode_per_s": rate(lambda: c.data_frame(17, 42, b"x" * 100), seconds),
        "frame_decode_per_s": rate(lambda: c.decode(wire), seconds),
        "frame_decode_crc_per_s": rate(lambda: c.crc_ok(wire, c.decode(wire)), seconds),
    }


# Hand-written decoder of the SW9 EYEQ_VIS_OBSTACLES_MSG for comparison: what a careful engineer
# would write for this one layout — struct.unpack_from, the same nested-dict output shape (struct
# members by name), bitfields split — but no spec, no E2E check, no other SW version.
_PHYS_NAMES = [
    "width",
    "widthStd",
    "length",
    "lengthStd",
    "height",
    "heightStd",
    "absoluteLongVelocity",
    "absoluteLongVelocityStd",
    "absoluteLatVelocity",
    "absoluteLatVelocityStd",
    "absoluteLongAcc",
    "absoluteLongAccStd",
    "absoluteLatAcc",
    "absoluteLatAccStd",
    "longDistance",
    "longDistanceStd",
    "latDistance",
    "latDistanceStd",
    "heading",
]
_ANG_NAMES = [
    "angleRight",
    "angleRightStd",
    "angleLeft",
    "angleLeftStd",
    "angleSide",
    "angleSideStd",
    "angleMid",
    "angleMidStd",
    "angularSpeed",
    "angularSpeedStd",
]
_PHYS = struct.Struct("<19f")
_ANG = struct.Struct("<10f")
_BOX = struct.Struct("<hhbb" + "hhhB" * 4 + "BB")
_TAIL = struct.Struct("<BBBffIHHBBBbBB")


def hand_decode_obstacles(buf: bytes, off: int = 4) -> dict[str, Any]:
    ts_ms, ts_us, frame, veh, crc = struct.unpack_from("<IQIIH", buf, off)
    pos = off + 22
    objs = []
    for _ in range(15):
        phys = dict(zip(_PHYS_NAMES, _PHYS.unpack_from(buf, pos), strict=True))
        ang = dict(zip(_ANG_NAMES, _ANG.unpack_from(buf, pos + 76), strict=True))
        b = _BOX.unpack_from(buf, pos + 116)
        edges = [
            {
                "xCoord": b[4 + 4 * i],
                "yTopCoord": b[5 + 4 * i],
                "yBottomCoord": b[6 + 4 * i],
                "isOccluded": b[7 + 4 * i] & 1,
                "valid": b[7 + 4 * i] >> 1 & 1,
            }
            for i in range(4)
        ]
        box = {
            "rect": {
                "xLeftCoord": b[0],
                "xRightCoord": b[1],
                "yTopCoord": b[2],
                "yBottomCoord": b[3],
            },
            "verticalEdges": edges,
            "visibleRect": b[20],
            "visibleSide": b[21],
        }
        (ms, mc, mo, conf, ttc, age, oid, ocrc, orfc, cls, cipv, lane, light, bits) = (
            _TAIL.unpack_from(buf, pos + 152)
        )
        objs.append(
            {
                "physicalState": phys,
                "angularState": ang,
                "imageBox": box,
                "mobilityState": {
                    "motionStatus": ms,
                    "motionCategory": mc,
                    "motionOrientation": mo,
                },
                "confidence": conf,
                "ttc_const_vel": ttc,
                "age": age,
                "id": oid,
                "crc_16": ocrc,
                "rollingFrameCount": orfc,
                "classification": cls,
                "isCipv": cipv,
                "laneAssignment": lane,
                "lightIndicators": {
                    "valid": light & 1,
                    "brake": light >> 1 & 1,
                    "turnRight": light >> 2 & 1,
                    "turnLeft": light >> 3 & 1,
                },
                "isPredicted": bits & 1,
                "isInDrivableArea": bits >> 1 & 1,
                "isVeryClose": bits >> 2 & 1,
            }
        )
        pos += 177
    image_index, rfc = struct.unpack_from("<HB", buf, pos)
    return {
        "timestamp_ms": ts_ms,
        "visObjects": {
            "timestamp_us": ts_us,
            "frameIndex": frame,
            "vehIndexUsed": veh,
            "crc_16": crc,
            "visObs": objs,
            "imageIndex": image_index,
            "rollingFrameCount": rfc,
        },
    }


def obstacles_bench(seconds: float) -> dict[str, float]:
    try:
        from tests.strategies import layout_values
    except ImportError as exc:  # hypothesis: the [test] extra
        raise SystemExit(f"bench.py: the obstacles benchmark needs the test extra ({exc}): "
                         "python -m pip install -e '.[test]', or --emulator-only") from None

    codec = MessageCodec("sw9")
    msg = codec.message("EYEQ_VIS_OBSTACLES_MSG")
    lay = codec.layout(msg)
    values = layout_values(codec.cat, lay).example()
    wire = codec.encode_dasp(msg.name, values, 0, E2EState())
    assert len(wire) == 4 + 2680
    hand = hand_decode_obstacles(wire)
    decoded = codec.decode(wire).fields
    assert hand == decoded, "the hand-written decoder must agree with the specs-built codec"
    # rounds interleave the decoders so that a loaded machine slows all of them alike; the goal
    # is the ratio of the codec with E2E (16 CRCs; with a state also the 16 rolling
    # counters) to the hand-written struct decoder, median over the rounds
    fns = {
        "obstacles_decode_us_specs_codec_with_e2e": lambda: codec.decode(wire),
        "obstacles_decode_us_specs_codec_with_e2e_state": lambda: codec.decode(wire, E2EState()),
        "obstacles_decode_us_specs_codec_no_e2e": lambda: lay.parse(wire[4:]),
        "obstacles_decode_us_hand_struct_unpack": lambda: hand_decode_obstacles(wire),
    }
    us: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(7):
        for k, fn in fns.items():
            us[k].append(1e6 / rate(fn, seconds / 7))
    hand_us = us["obstacles_decode_us_hand_struct_unpack"]
    out: dict[str, float] = {}
    for k, v in us.items():
        out[k] = statistics.median(v)
        out[k + "_min"], out[k + "_max"] = min(v), max(v)
        if k != "obstacles_decode_us_hand_struct_unpack":
            out[k.replace("_us_", "_x_hand_")] = statistics.median(
                a / b for a, b in zip(v, hand_us, strict=True))
    encode_rate = rate(lambda: codec.encode_dasp(msg.name, values, 0, E2EState()), seconds)
    out["obstacles_encode_us_specs_codec_with_e2e"] = 1e6 / encode_rate
    return out


class _TimedNode:
    """Wraps a node and adds up the CPU time spent inside it (the host-alone figure). Each
    measured interval also holds part of the clock reads themselves: :meth:`corrected` takes
    off ``calls`` times the bias of an empty interval, calibrated in the same run."""

    def __init__(self, node: Any) -> None:
        self.node, self.cpu, self.calls = node, 0.0, 0

    def receive_data(self, transfer: bytes, now: float) -> None:
        c = time.thread_time()
        self.node.receive_data(transfer, now)
        self.cpu += time.thread_time() - c
        self.calls += 1

    def data_to_send(self, now: float) -> list[bytes]:
        c = time.thread_time()
        out: list[bytes] = self.node.data_to_send(now)
        self.cpu += time.thread_time() - c
        self.calls += 1
        return out

    def get_timer(self) -> float | None:
        c = time.thread_time()
        t: float | None = self.node.get_timer()
        self.cpu += time.thread_time() - c
        self.calls += 1
        return t

    def handle_timer(self, now: float) -> None:
        c = time.thread_time()
        self.node.handle_timer(now)
        self.cpu += time.thread_time() - c
        self.calls += 1

    def corrected(self) -> float:
        empty = _TimedNode(None)
        n = 100_000
        for _ in range(n):
            c = time.thread_time()
            empty.cpu += time.thread_time() - c
        return max(0.0, self.cpu - self.calls * empty.cpu / n)


def crc_baseline_us() -> float:
    """The in-run baseline: µs of CPU for one ``binascii.crc_hqx`` over a 128-byte frame."""
    frame = bytes(range(128))
    n = 200_000
    c = time.thread_time()
    for _ in range(n):
        binascii.crc_hqx(frame, 0xFFFF)
    return (time.thread_time() - c) / n * 1e6


def _one_demo(virtual_s: float, full: bool, timed_host: bool,
              dasp_packer: bool = True) -> dict[str, float]:
    from eyeq_spi.emulator import build
    from eyeq_spi.host.machine import HostState
    from eyeq_spi.sim.config import SimConfig

    cfg = SimConfig(objects=15, signs=20, light_spots=15, dasp_packer=dasp_packer) if full \
        else SimConfig(dasp_packer=dasp_packer)
    emu = build(sim_config=cfg, keep_rx_times=False)
    host = None
    if timed_host:
        host = _TimedNode(emu.host)
        emu.runner.nodes[0] = (host, emu.runner.nodes[0][1])
    emu.run_for(virtual_s)
    assert emu.host.state is HostState.RUNNING_VISION
    out = {"wall_s": emu.runner.wall_s, "cpu_per_sim_s": emu.runner.cpu_s / virtual_s}
    if host is not None:
        out["host_cpu_per_sim_s"] = host.corrected() / virtual_s
    return out


def emulator_bench(runs: int = 3, long_s: float = 0.0, dasp_packer: bool = True
                   ) -> dict[str, float]:
    """``demo --virtual-time`` at full load (15 objects, 20 signs, 15 light spots): wall time
    per 60 s of virtual time, CPU-s per simulated second for host + simulated EyeQ and for the
    host alone (CPU inside the host's node calls), median and spread of ``runs`` runs, and each
    as a ratio to the in-run CRC baseline (how many 128-byte ``crc_hqx`` calls the same CPU
    time buys). ``long_s``: one more run of that many virtual seconds (600 s for
    the ten-minute figure)."""
    out: dict[str, float] = {}
    crc = [crc_baseline_us()]
    rows = []
    for _ in range(runs):
        rows.append(_one_demo(60.0, True, False, dasp_packer))
        rows.append({**_one_demo(10.0, True, True, dasp_packer), "wall_s": math.nan})
        crc.append(crc_baseline_us())
    base = statistics.median(crc)
    out["crc_hqx_128B_us_baseline"] = base
    for key, label in (("wall_s", "emulator_full_wall_s_per_60s_virtual"),
                       ("cpu_per_sim_s", "emulator_full_cpu_s_per_sim_s"),
                       ("host_cpu_per_sim_s", "emulator_host_alone_cpu_s_per_sim_s")):
        # host + EyeQ from the untimed runs only: the timed ones add the clock reads
        vals = [r[key] for r in rows if key in r and not math.isnan(r[key])
                and (key == "host_cpu_per_sim_s" or "host_cpu_per_sim_s" not in r)]
        out[label] = statistics.median(vals)
        out[label + "_min"] = min(vals)
        out[label + "_max"] = max(vals)
        if key != "wall_s":
            out[label + "_in_crc_calls"] = statistics.median(vals) / (base * 1e-6)
    out["emulator_full_x_real_time"] = 60.0 / out["emulator_full_wall_s_per_60s_virtual"]
    if long_s:
        r = _one_demo(long_s, True, False, dasp_packer)
        out[f"emulator_full_wall_s_per_{long_s:g}s_virtual"] = r["wall_s"]
        out[f"emulator_full_x_real_time_{long_s:g}s"] = long_s / r["wall_s"]
    return out


def _dasp_cpu_per_sim_s(packer: bool, virtual_s: float) -> float:
    """CPU-s per simulated second of the simulated EyeQ's DASP generation alone at full load
    (``_send_due_dasp``: due heap, scene step, fill, pack, E2E; the link's ``_send`` stubbed)."""
    from eyeq_spi.catalog.bringup import RUNNING_VISION
    from eyeq_spi.sim.config import SimConfig
    from eyeq_spi.sim.eyeq import Phase, SimulatedEyeQ

    sim = SimulatedEyeQ(SimConfig(objects=15, signs=20, light_spots=15, dasp_packer=packer))
    sim.warm_up()
    sim.phase, sim.main_state = Phase.RUNNING, RUNNING_VISION
    sim._send = lambda message, now: None  # type: ignore[method-assign]
    sim._send_due_dasp(0.0)
    c = time.thread_time()
    while sim._dasp_min < virtual_s:
        sim._send_due_dasp(sim._dasp_min)
    return (time.thread_time() - c) / virtual_s


def dasp_bench(runs: int = 3, virtual_s: float = 20.0) -> dict[str, float]:
    """The simulated EyeQ's DASP generation: the packer (sim/dasp_fast.py) against the
    dict path (Scene.fill + encode_dasp) in interleaved runs, median and spread, the ratio, and
    each in 128-byte ``crc_hqx`` calls of the in-run baseline."""
    rows: dict[bool, list[float]] = {False: [], True: []}
    crc = [crc_baseline_us()]
    for _ in range(runs):
        for packer in (False, True):
            rows[packer].append(_dasp_cpu_per_sim_s(packer, virtual_s))
        crc.append(crc_baseline_us())
    out = _pair_summary(rows, ("dasp_dict_path", "dasp_packer"), statistics.median(crc))
    out["dasp_dict_over_packer"] = (out["dasp_dict_path_cpu_ms_per_sim_s"]
                                    / out["dasp_packer_cpu_ms_per_sim_s"])
    return out


def dasp_before_bench(before: str, runs: int = 5, virtual_s: float = 20.0,
                      packer: bool = True) -> dict[str, float]:
    """The DASP generation of :func:`_dasp_cpu_per_sim_s` in this tree against git revision
    ``before`` (each tree's own ``tools/bench.py``, which puts its tree first on the path): each
    run a fresh process, the trees alternating round by round (a change of the machine's load
    hits both), median and spread of each, the ratio, in ``crc_hqx`` calls."""
    import os
    import subprocess
    import tempfile
    from pathlib import Path

    from bench_startup import trees_to_time

    code = ("import sys; sys.path.insert(0, {tools!r}); import bench; "
            "print(bench._dasp_cpu_per_sim_s({packer}, {s!r}))")
    rows: dict[bool, list[float]] = {False: [], True: []}
    crc = [crc_baseline_us()]
    with tempfile.TemporaryDirectory() as d:
        (_, old_tree), (_, new_tree) = trees_to_time(before, Path(d))
        for _ in range(runs):
            for after, tree in ((False, old_tree), (True, new_tree)):
                got = subprocess.run(
                    [sys.executable, "-c", code.format(tools=str(tree / "tools"),
                                                       packer=packer, s=virtual_s)],
                    env={**os.environ, "PYTHONPATH": str(tree)}, cwd=d, check=True,
                    capture_output=True, text=True).stdout
                rows[after].append(float(got))
            crc.append(crc_baseline_us())
    out = _pair_summary(rows, ("dasp_before", "dasp_after"), statistics.median(crc))
    out["dasp_after_over_before"] = (out["dasp_after_cpu_ms_per_sim_s"]
                                     / out["dasp_before_cpu_ms_per_sim_s"])
    return out


def _pair_summary(rows: dict[bool, list[float]], labels: tuple[str, str],
                  base_us: float) -> dict[str, float]:
    """CPU-ms per simulated second of the reference (``rows[False]``) and the fast path
    (``rows[True]``): median, min, max, and the median in ``crc_hqx`` calls of ``base_us``."""
    out: dict[str, float] = {}
    for fast, label in zip((False, True), labels, strict=True):
        vals = rows[fast]
        out[f"{label}_cpu_ms_per_sim_s"] = statistics.median(vals) * 1e3
        out[f"{label}_cpu_ms_per_sim_s_min"] = min(vals) * 1e3
        out[f"{label}_cpu_ms_per_sim_s_max"] = max(vals) * 1e3
        out[f"{label}_in_crc_calls"] = statistics.median(vals) / (base_us * 1e-6)
    return out


def _tapped(virtual_s: float) -> list[tuple[str, float, bytes]]:
    """The transfers of a full-load ``demo --virtual-time`` run, as its ``--capture`` tap sees
    them."""
    from eyeq_spi.emulator import build
    from eyeq_spi.sim.config import SimConfig

    out: list[tuple[str, float, bytes]] = []
    emu = build(sim_config=SimConfig(objects=15, signs=20, light_spots=15),
                keep_rx_times=False,
                tap=lambda node, t, x: out.append(("h2e" if node == 0 else "e2h", t, x)))
    emu.run_for(virtual_s)
    return out


def _capture_cpu_per_sim_s(records: list[tuple[str, float, bytes]], virtual_s: float) -> float:
    import tempfile

    from eyeq_spi.capture.pcapng_io import CaptureWriter

    with tempfile.TemporaryDirectory() as d:
        w = CaptureWriter(Path(d) / "c.pcapng", idle_flush=False)
        write = w.write
        c = time.thread_time()  # from the first write to the file closed
        for direction, t, x in records:
            write(direction, t, x)
        w.close()
        return (time.thread_time() - c) / virtual_s


def capture_bench(runs: int = 3, virtual_s: float = 20.0) -> dict[str, float]:
    """``--capture`` in a full-load virtual-time run: CPU per simulated second of writing its
    transfers (the tap's ``CaptureWriter.write`` calls, encoding and file writes), median and
    spread, and in 128-byte ``crc_hqx`` calls of the in-run baseline."""
    records = _tapped(virtual_s)
    rows = [_capture_cpu_per_sim_s(records, virtual_s) for _ in range(runs)]
    base = statistics.median([crc_baseline_us() for _ in range(3)])
    med = statistics.median(rows)
    return {"capture_transfers_per_sim_s": len(records) / virtual_s,
            "capture_cpu_ms_per_sim_s": med * 1e3, "capture_cpu_ms_per_sim_s_min": min(rows) * 1e3,
            "capture_cpu_ms_per_sim_s_max": max(rows) * 1e3,
            "capture_in_crc_calls": med / (base * 1e-6)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=1.0, help="time per measurement")
    ap.add_argument("--no-emulator", action="store_true", help="skip the emulator runs")
    ap.add_argument("--emulator-only", action="store_true", help="only the emulator runs")
    ap.add_argument("--runs", type=int, default=3, help="emulator runs (median and spread)")
    ap.add_argument("--long", type=float, default=0.0, metavar="S",
                    help="one more emulator run of S virtual seconds (e.g. 600 for ten minutes)")
    ap.add_argument("--dasp-dict", action="store_true",
                    help="emulator runs with the simulated EyeQ's DASP dict path (the reference "
                         "the packer is held to) instead of the packer")
    ap.add_argument("--capture-only", action="store_true",
                    help="only the --capture writer")
    ap.add_argument("--dasp-before", metavar="REV",
                    help="only the DASP generation, this tree against git revision REV in "
                         "alternating fresh processes (--runs rounds; --dasp-dict: the dict path)")
    args = ap.parse_args()
    out: dict[str, float] = {}
    if args.dasp_before:
        out.update(dasp_before_bench(args.dasp_before, args.runs, packer=not args.dasp_dict))
        args.no_emulator = args.emulator_only = True
    if args.capture_only:
        out.update(capture_bench(args.runs))
        args.no_emulator = args.emulator_only = True
    if not args.emulator_only:
        out.update({**frame_bench(args.seconds), **obstacles_bench(args.seconds)})
    if not args.no_emulator:
        out.update(emulator_bench(args.runs, args.long, not args.dasp_dict))
        out.update(dasp_bench(args.runs))
        out.update(capture_bench(args.runs))
    for k, v in out.items():
        print(f"{k:55s} {v:14,.4g}")
    print(json.dumps({k: float(f"{v:.4g}") for k, v in out.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
