"""Scene extraction (no plotting library needed) and the synthetic captures the plot and monitor
tests draw: known objects, lanes and signs encoded by the real codec, segmented by the real
transport, framed by the real frame codec and written as hex or pcapng."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.link.frame import FrameCodec
from eyeq_spi.plot.perceived import (
    OBSTACLES,
    ROAD,
    SIGNS,
    Labels,
    SceneTracker,
    lines,
    objects,
    signs,
)
from eyeq_spi.transport.segment import segment

# (id, classification, longDistance, latDistance, width, length, isCipv, vlong)
OBJECTS = [
    (3, 0, 20.0, 0.0, 2.0, 4.5, 2, 20.0),   # car, CIPV, straight ahead
    (5, 1, 35.0, 8.0, 2.5, 12.0, 1, 18.0),  # truck on the left
    (9, 4, 12.0, -6.0, 1.5, 1.5, 0, 0.0),   # pedestrian on the right (box big enough to see)
]
# marker name -> (a0, a1, a2, a3, start, end, type)
LINES = {
    "hostLeftMarker": (2.5, 0.01, 0.0015, -1e-5, 5.0, 45.0, 1),    # SOLID, curving left
    "hostRightMarker": (-2.5, 0.01, 0.0015, -1e-5, 5.0, 45.0, 1),
}
SIGNS_AT = [(30.0, -7.0, 4), (50.0, 7.5, 9)]  # long, lat, signType (e_std_50, e_std_100)


def _fill_scene(codec: MessageCodec, t: float) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    obs = codec.layout(codec.message(OBSTACLES)).zero_values()
    elems = obs["visObjects"]["visObs"]
    for i, (oid, cls, lo, la, w, ln, cipv, v) in enumerate(OBJECTS):
        e = elems[i]
        e["id"], e["classification"], e["isCipv"] = oid, cls, cipv
        ps = e["physicalState"]
        ps.update(longDistance=lo, latDistance=la, width=w, length=ln, absoluteLongVelocity=v)
        if "ttc_const_vel" in e:
            e["ttc_const_vel"] = 7.0
    out[OBSTACLES] = obs
    road = codec.layout(codec.message(ROAD)).zero_values()
    rm = road["roadInfo"]["roadMarkerInfo"]
    for name in ("nextLeftLeftMarker", "nextLeftRightMarker", "nextRightRightMarker",
                 "nextRightLeftMarker"):
        rm[name]["laneMarkerType"] = 6  # INVALID
    for name, (a0, a1, a2, a3, s, e2, typ) in LINES.items():
        m = rm[name]
        m["laneMarker"].update(a0=a0, a1=a1, a2=a2, a3=a3, startRange=s, endRange=e2)
        m["laneMarkerType"] = typ
    out[ROAD] = road
    tsr = codec.layout(codec.message(SIGNS)).zero_values()
    info = tsr["tsrInfo"]
    for i, (lo, la, typ) in enumerate(SIGNS_AT):
        # SIGNS_AT is in the plot's frame (lateral left positive); §16 sends right positive
        info["trafficSigns"][i].update(signLongPosition=lo, signLatPosition=-la, signType=typ,
                                       signHeight=2.0)
    info["numberTrafficSigns"] = len(SIGNS_AT)
    out[SIGNS] = tsr
    return out


def scene_messages(codec: MessageCodec, duration: float = 1.0, rate: float = 18.0,
                   stop: dict[str, tuple[float, float]] | None = None
                   ) -> list[tuple[float, str, bytes]]:
    """(time, name, wire bytes) of the three scene messages at ``rate`` Hz; a stream in
    ``stop`` sends nothing in [from, to), its DASP counter running on as if the messages were
    lost on the way (so the first one after the silence is a counter jump)."""
    stop = stop or {}
    e2e = E2EState()
    counters: dict[str, int] = {}
    out = []
    n = int(duration * rate)
    for k in range(n):
        t = k / rate
        for j, (name, values) in enumerate(_fill_scene(codec, t).items()):
            c = counters.get(name, 0)
            counters[name] = (c + 1) & 0xFF
            a, b = stop.get(name, (float("inf"), 0.0))
            if a <= t < b:
                continue
            out.append((t + j * 0.002, name, codec.encode_dasp(name, values, c, e2e)))
    return out


def frames_of(messages: list[tuple[float, str, bytes]]) -> list[tuple[float, str, bytes]]:
    """EyeQ -> host DATA frames and the host's ACKs, 50 µs apart."""
    fc = FrameCodec()
    num, tid = 0, 0
    out = []
    for t, _, wire in messages:
        for k, payload in enumerate(segment(wire, tid)):
            tt = t + k * 100e-6
            out.append((tt, "e2h", fc.data_frame(0, num, payload)))
            out.append((tt + 50e-6, "h2e", fc.ack(num)))
            num = (num + 1) % 4096
        tid = (tid + 1) % 256
    return out


def write_capture(path: Path, frames: list[tuple[float, str, bytes]]) -> Path:
    from eyeq_spi.capture.pcapng_io import CaptureWriter

    with CaptureWriter(path) as w:
        for t, d, data in frames:
            w.write(d, t, data)
    return path


def synthetic_capture(path: Path, duration: float = 1.0,
                      stop: dict[str, tuple[float, float]] | None = None) -> Path:
    codec = MessageCodec(None)
    return write_capture(path, frames_of(scene_messages(codec, duration, stop=stop)))


def test_scene_from_decoded_fields() -> None:
    codec = MessageCodec(None)
    lab = Labels(codec)
    values = _fill_scene(codec, 0.0)
    objs = objects(values[OBSTACLES], lab)
    assert [(o.id, o.long, o.lat, o.cipv) for o in objs] == [
        (3, 20.0, 0.0, True), (5, 35.0, 8.0, False), (9, 12.0, -6.0, False)]
    assert [o.cls_name for o in objs] == ["car", "truck", "pedestrian"]
    lns = lines(values[ROAD], lab)
    assert {ln.name for ln in lns} == set(LINES)  # INVALID and empty-range lines are skipped
    left = next(ln for ln in lns if ln.name == "hostLeftMarker")
    assert left.type_name == "SOLID"
    assert left.lateral(10.0) == pytest.approx(2.5 + 0.1 + 0.0015 * 100 - 0.01)
    sg = signs(values[SIGNS], lab)
    assert [(s.long, s.lat) for s in sg] == [(30.0, -7.0), (50.0, 7.5)]
    assert sg[0].name == "Speed Limit 50"


def test_invalid_ids_and_decode_errors_are_not_drawn() -> None:
    codec = MessageCodec(None)
    lab = Labels(codec)
    values = _fill_scene(codec, 0.0)
    values[OBSTACLES]["visObjects"]["visObs"][0]["id"] = 0  # "any other value: invalid"
    values[OBSTACLES]["visObjects"]["visObs"][1]["id"] = 200
    assert [o.id for o in objects(values[OBSTACLES], lab)] == [9]
    tr = SceneTracker(lab)
    assert not tr.update(OBSTACLES, values[OBSTACLES], 0.0, ["wrong length"])
    assert tr.update(OBSTACLES, values[OBSTACLES], 0.0, ["E2E crc_16 mismatch"])
    assert not tr.update("EYEQ_SAFETY_MSG", {"x": 1}, 0.0)


def test_every_release_has_a_scene() -> None:
    """The scene is found by members, not by per-release paths: every SW release decodes."""
    for sw in ("sw2_2", "sw5", "sw8_1", "sw9"):
        codec = MessageCodec(sw)
        lab = Labels(codec)
        obs = codec.layout(codec.message(OBSTACLES)).zero_values()
        obs["visObjects"]["visObs"][0]["id"] = 1
        obs["visObjects"]["visObs"][0]["physicalState"]["longDistance"] = 12.5
        wire = codec.encode_dasp(OBSTACLES, obs, 0, E2EState())
        dec = codec.decode(wire, E2EState())
        assert [o.long for o in objects(dec.fields, lab)] == [12.5], sw
