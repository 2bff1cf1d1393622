"""CAN logs shaped like a production Mobileye ExtLogData2 camera's, for the decoder's tests and
``tools/bench_can.py``.

The camera sits on channel ``CAMERA`` of a four-channel log, beside a radar (``RADAR``: its own
0x650 every 40.5 ms and radar IDs) and vehicle buses (``VEHICLE``: 0x773/0x778, which are
Next_Lane IDs of the protocol, and others). What the camera sends follows decisions C5-C9:

- cycles of 75-81 ms (the seed says 66 ms), 0x669 at about 80 ms (the seed says 100 ms);
- the LKA "B" frames 0x767/0x769/0x76D/0x76F with DLC 4;
- Car_Info on 0x760, obstacles only in slots 0..12;
- 0x650 Fixed_FOE as big-endian binary32 (40.0 px, 10.25 px);
- Obstacle_Scale_Change 0x7FFF for objects younger than 4 frames, Failsafe 0, brake lights
  off, Ref_Point_2 raw 0 (its exact minimum);
- Obstacle_Pos_Y left positive and Obstacle_Angle right positive (opposite signs).

The frames the C5-C9 tests look at are packed by hand here (``struct``), not with the project's
DBC, so a wrong spec cannot agree with itself. ``python -m tests.camera_can OUT.blf`` writes one.
"""

from __future__ import annotations

import math
import random
import struct
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CAMERA, RADAR, VEHICLE, BODY = 1, 2, 0, 3
FOE_YAW, FOE_HORIZON = 40.0, 10.25
B_IDS = (0x767, 0x769, 0x76D, 0x76F)


@dataclass
class CameraLog:
    path: Path
    frames: int = 0
    per_channel: dict[int, int] = field(default_factory=dict)
    camera_ids: set[int] = field(default_factory=set)


def _le(fields: list[tuple[int, int, int]], dlc: int = 8) -> bytes:
    """Little-endian packing of (start, length, raw) triples (two's complement for negatives)."""
    v = 0
    for start, length, raw in fields:
        v |= (raw & ((1 << length) - 1)) << start
    return v.to_bytes(8, "little")[:dlc]


def _obstacle(i: int, age: int, t: float) -> tuple[bytes, bytes, bytes]:
    x = 12.0 + 9.0 * i + 2.0 * math.sin(t / 3 + i)
    y = (-1) ** i * (1.0 + 0.7 * i)  # left positive on the wire (C5)
    angle = -math.degrees(math.atan2(y, x))  # right positive: opposite sign of y
    a = _le([(0, 8, i + 1), (8, 12, round(x / 0.0625)), (24, 10, round(y / 0.0625)),
             (34, 3, 1), (37, 3, 1), (40, 12, round(-1.5 / 0.0625)), (52, 3, 0),
             (56, 3, 3), (59, 1, 0), (62, 2, 1 if age <= 1 else 2)])
    b = _le([(0, 8, 9), (8, 8, 36), (16, 8, min(age, 254)), (24, 2, 1), (26, 1, int(i == 0)),
             (28, 12, 0xFFF), (40, 12, 0x800), (52, 3, 0), (56, 7, 0x7F)])
    scale = 0x7FFF if age < 4 else round(0.01 / 0.0002)  # C8: 0x7FFF while young
    c = _le([(0, 16, round(0.3 / 0.01)), (16, 16, scale), (32, 10, 0), (44, 1, 0),
             (48, 16, round(angle / 0.01))])
    return a, b, c


def _lka_a(c0: float) -> bytes:
    c2 = round(0.0001 / 9.765625e-07) + 0x7FFF
    return _le([(0, 4, 1), (4, 2, 3), (6, 2, 3), (8, 16, round(c0 / 0.00390625)),
                (24, 16, c2), (40, 16, 0x7FFF), (56, 8, 12)])


def camera_cycle(n: int, t: float, rng: random.Random) -> list[tuple[int, bytes]]:
    """The frames of one camera cycle (ID, payload)."""
    out: list[tuple[int, bytes]] = []
    out.append((0x650, struct.pack(">ff", FOE_YAW, FOE_HORIZON)))  # C6: big-endian floats
    out.append((0x700, _le([(16, 1, 1), (17, 7, 18), (32, 1, 1), (56, 2, 1)])))
    out.append((0x727, bytes([3, 0, 254, 0, 254, 0, 254, 0])))
    out.append((0x728, bytes([1, 0, 0])))
    out.append((0x729, _le([(0, 8, 100), (8, 12, 150), (20, 12, 250), (32, 8, 40),
                            (40, 2, 1), (42, 2, 1), (44, 2, 1), (46, 2, 1)])))
    curv = round(0.0002 / 3.81e-6)
    out.append((0x737, _le([(0, 16, curv), (16, 12, 10), (29, 1, 1), (30, 1, 1),
                            (32, 16, 0x7FFF + 20), (48, 16, 0x7FFF - 300)])))
    nobj = 5
    out.append((0x738, _le([(0, 8, nobj), (8, 8, n % 256), (16, 8, 3), (24, 2, n % 4),
                            (28, 4, 15), (40, 1, 0), (41, 4, 0)], dlc=6)))  # Failsafe 0
    for i in range(nobj):
        a, b, c = _obstacle(i, age=1 + (n + 3 * i) % 40, t=t)
        out += [(0x739 + 3 * i, a), (0x73A + 3 * i, b), (0x73B + 3 * i, c)]
    speed = 50 + (n % 20)
    out.append((0x760, bytes([0, 0b1100_1111, speed, 0, 0, 0, 0, 0])))  # C7: Car_Info
    out.append((0x766, _lka_a(-1.7)))  # left lane: C0 negative (right positive)
    out.append((0x767, _le([(0, 16, 0x7FFF + 5), (16, 15, round(60 / 0.00390625)),
                            (31, 1, 1)], dlc=4)))  # C8: DLC 4
    out.append((0x768, _lka_a(1.8)))
    out.append((0x769, _le([(0, 16, 0x7FFF + 5), (16, 15, round(55 / 0.00390625)),
                            (31, 1, 1)], dlc=4)))
    out.append((0x76A, _le([(0, 16, 0x7FFF + 20), (16, 15, round(20 / 0.00390625)), (31, 1, 1),
                            (32, 16, 0), (48, 15, 0), (63, 1, 0)])))  # Ref_Point_2 raw 0
    out.append((0x76B, bytes([2, 0, 0, 0, 0, 0, 0, 0])))
    out.append((0x76C, _lka_a(-5.3)))
    out.append((0x76D, _le([(0, 16, 0x7FFF), (16, 15, 0), (31, 1, 0)], dlc=4)))
    out.append((0x76E, _lka_a(5.4)))
    out.append((0x76F, _le([(0, 16, 0x7FFF), (16, 15, 0), (31, 1, 0)], dlc=4)))
    rng.shuffle(out)
    return out


def lane_669() -> bytes:
    return _le([(0, 2, 3), (2, 1, 1), (4, 4, 1), (12, 12, round(-1.7 / 0.02)),
                (40, 2, 3), (42, 1, 1), (44, 4, 0), (52, 12, round(1.8 / 0.02))])


def messages(seconds: float = 20.0, seed: int = 1) -> list[Any]:
    """python-can messages of the whole log, in time order."""
    import can

    rng = random.Random(seed)
    t0 = 1_700_000_000.0
    events: list[tuple[float, int, int, bytes]] = []
    t, n = 0.0, 0
    while t < seconds:  # camera: 75-81 ms cycles, frames spread over 3 ms
        for k, (fid, data) in enumerate(camera_cycle(n, t, rng)):
            events.append((t + k * 0.0001, CAMERA, fid, data))
        t += rng.uniform(0.075, 0.081)
        n += 1
    t = 0.01
    while t < seconds:  # 0x669 at ~80 ms (the seed says 100 ms)
        events.append((t, CAMERA, 0x669, lane_669()))
        t += rng.uniform(0.079, 0.081)
    t = 0.003
    while t < seconds:  # the radar's own 0x650 and tracks
        events.append((t, RADAR, 0x650, bytes(rng.getrandbits(8) for _ in range(8))))
        for k in range(4):
            events.append((t + 0.001 * k, RADAR, 0x500 + k, rng.randbytes(8)))
        t += 0.0405
    t = 0.005
    while t < seconds:  # vehicle buses: IDs that are also Next_Lane slots of the protocol
        events.append((t, VEHICLE, 0x773, rng.randbytes(8)))
        events.append((t + 0.002, VEHICLE, 0x778, rng.randbytes(8)))
        events.append((t + 0.004, BODY, 0x1A0, rng.randbytes(6)))
        t += 0.02
    events.sort(key=lambda e: e[0])
    return [can.Message(timestamp=t0 + tt, arbitration_id=fid, data=data, dlc=len(data),
                        is_extended_id=False, channel=ch) for tt, ch, fid, data in events]


def write(path: Path, seconds: float = 20.0, seed: int = 1) -> CameraLog:
    """Write the log with python-can's writer for ``path``'s suffix (.blf .asc .log .trc)."""
    import can

    info = CameraLog(path)
    w = can.Logger(str(path))
    try:
        for m in messages(seconds, seed):
            w.on_message_received(m)
            info.frames += 1
            info.per_channel[m.channel] = info.per_channel.get(m.channel, 0) + 1
            if m.channel == CAMERA:
                info.camera_ids.add(m.arbitration_id)
    finally:
        w.stop()
    return info


def truncated_copy(src: Path, dst: Path, fraction: float = 0.5) -> Path:
    """``src`` cut at ``fraction`` of its bytes, inside a record (one byte into a line or a
    container)."""
    data = src.read_bytes()
    cut = int(len(data) * fraction)
    if src.suffix.lower() != ".blf":  # inside a line, never at its end
        while data[cut - 1:cut] in (b"\n", b"") and cut > 1:
            cut -= 1
    dst.write_bytes(data[:cut])
    return dst


def camera_channel(suffix: str) -> str:
    """How python-can's reader names the camera's channel in a log of this format."""
    return {".log": f"can{CAMERA}", ".trc": str(CAMERA + 1)}.get(suffix, str(CAMERA))


if __name__ == "__main__":
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "camera.blf")
    secs = float(sys.argv[2]) if len(sys.argv) > 2 else 20.0
    info = write(out, secs)
    print(f"{out}: {info.frames} frames, per channel {info.per_channel}")
