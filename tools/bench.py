#!/usr/bin/env python3
"""Benchmarks (figures go in the closing note and README, never in timed unit tests).

- frame codec: encode and decode frames/s;
- EYEQ_VIS_OBSTACLES_MSG with 15 objects: µs per decode with the specs-built construct codec,
  beside a hand-written ``struct.unpack_from`` decoder of the same SW9 layout in the same run.
"""

from __future__ import annotations

import argparse
import json
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
    from tests.strategies import layout_values

    codec = MessageCodec("sw9")
    msg = codec.message("EYEQ_VIS_OBSTACLES_MSG")
    lay = codec.layout(msg)
    values = layout_values(codec.cat, lay).example()
    wire = codec.encode_dasp(msg.name, values, 0, E2EState())
    assert len(wire) == 4 + 2680
    hand = hand_decode_obstacles(wire)
    decoded = codec.decode(wire).fields
    assert hand == decoded, "the hand-written decoder must agree with the specs-built codec"
    spec_rate = rate(lambda: codec.decode(wire), seconds)
    noe2e = rate(lambda: lay.parse(wire[4:]), seconds)
    hand_rate = rate(lambda: hand_decode_obstacles(wire), seconds)
    encode_rate = rate(lambda: codec.encode_dasp(msg.name, values, 0, E2EState()), seconds)
    return {
        "obstacles_decode_us_specs_codec_with_e2e": 1e6 / spec_rate,
        "obstacles_decode_us_specs_codec_no_e2e": 1e6 / noe2e,
        "obstacles_decode_us_hand_struct_unpack": 1e6 / hand_rate,
        "obstacles_encode_us_specs_codec_with_e2e": 1e6 / encode_rate,
    }


def emulator_bench(seconds: float) -> dict[str, float]:
    """Demo wall time for 60 s of virtual time, and CPU per simulated second at full load."""
    from eyeq_spi.emulator import build
    from eyeq_spi.host.machine import HostState
    from eyeq_spi.sim.config import SimConfig

    out: dict[str, float] = {}
    for label, cfg in (
        ("default", SimConfig()),
        ("full", SimConfig(objects=15, signs=20, light_spots=15)),
    ):
        emu = build(sim_config=cfg, keep_rx_times=False)
        emu.run_for(60.0)
        assert emu.host.state is HostState.RUNNING_VISION
        out[f"emulator_{label}_wall_s_per_60s_virtual"] = emu.runner.wall_s
        out[f"emulator_{label}_cpu_ms_per_simulated_s"] = 1000 * emu.runner.cpu_s / 60.0
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=1.0, help="time per measurement")
    ap.add_argument("--no-emulator", action="store_true", help="skip the 2 x 60 s emulator runs")
    args = ap.parse_args()
    out = {**frame_bench(args.seconds), **obstacles_bench(args.seconds)}
    if not args.no_emulator:
        out.update(emulator_bench(args.seconds))
    for k, v in out.items():
        print(f"{k:45s} {v:14,.1f}")
    print(json.dumps({k: round(v, 1) for k, v in out.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
