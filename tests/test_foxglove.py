"""The Foxglove scene: known DASP values land where a hand computation says (vehicle frame, C5
signs, radians), through the real encoder, decoder and the SDK's schemas; ``export --mcap``
writes the scene topics beside its own, readable with the ``mcap`` reader and the SDK's
schemas, in the counts ``dissect --stats`` gives; the layout opens the scene, plots and log."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("foxglove", reason="the [foxglove] extra (foxglove-sdk) is not installed")
pytest.importorskip("google.protobuf", reason="protobuf (the test extra) decodes the scene")

import foxglove.messages as fgm

from eyeq_spi.cli import main
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.foxglove.feed import Feed
from eyeq_spi.plot.vehicle_frame import CAMERA_HEIGHT_M
from tests.foxglove_client import message_class

OBSTACLES = "EYEQ_VIS_OBSTACLES_MSG"
ROAD = "EYEQ_VIS_ROAD_DATA_MSG"
SIGNS = "EYEQ_VIS_TRAFFIC_SIGNS_MSG"
LIGHTS = "EYEQ_VIS_LIGHT_SENSOR_DATA_MSG"


class ListSink:
    """A Foxglove sink that keeps what it is given, encoded as a server or a file gets it."""

    def __init__(self) -> None:
        self.got: list[tuple[str, str, bytes, int]] = []  # topic, schema name, bytes, time

    def message(self, topic: str, msg: Any, log_time_ns: int) -> None:
        self.got.append((topic, msg.get_schema().name, msg.encode(), log_time_ns))

    def values(self, topic: str, schema: dict[str, Any], body: dict[str, Any],
               log_time_ns: int) -> None:
        self.got.append((topic, "json", json.dumps(body).encode(), log_time_ns))

    def decoded(self, topic: str) -> list[Any]:
        out = []
        for name, cls in (("foxglove.SceneUpdate", fgm.SceneUpdate),
                          ("foxglove.FrameTransform", fgm.FrameTransform)):
            schema = cls.get_schema()
            decode = message_class(schema.name, schema.data)
            out += [decode.FromString(data) for t, n, data, _ in self.got
                    if t == topic and n == name]
        return out


def _first(values: Any, key: str) -> dict[str, Any]:
    """The first dict under ``key`` (the first element if it is an array)."""
    if isinstance(values, dict):
        if key in values:
            found = values[key]
            return found[0] if isinstance(found, list) else found
        for inner in values.values():
            if isinstance(inner, dict | list):
                try:
                    return _first(inner, key)
                except KeyError:
                    pass
    elif isinstance(values, list) and values:
        return _first(values[0], key)
    raise KeyError(key)


def _set_count(values: dict[str, Any], key: str, count: int) -> None:
    parent = values
    while key not in parent:
        parent = next(v for v in parent.values() if isinstance(v, dict) and _has(v, key))
    parent[key] = count


def _has(values: dict[str, Any], key: str) -> bool:
    return key in values or any(isinstance(v, dict) and _has(v, key) for v in values.values())


def _wire(codec: MessageCodec, name: str, edit: Any) -> dict[str, Any]:
    """A DASP message with ``edit`` applied to its zero values, encoded and decoded again."""
    values = codec.layout(codec.message(name)).zero_values()
    edit(values)
    out = codec.decode(codec.encode_dasp(name, values, 0))
    assert not [e for e in out.errors if not e.startswith(("E2E", "DASP counter"))], out.errors
    return out.fields


def _obstacle(values: dict[str, Any]) -> None:
    obj = _first(values, "visObs")
    obj.update(id=3, classification=0, isCipv=2)  # object_is_cipv: 2 = CIPV
    obj["physicalState"].update(longDistance=20.0, latDistance=3.0, length=4.0, width=2.0,
                                height=1.6, heading=0.1)


def _road(values: dict[str, Any]) -> None:
    marker = _first(values, "hostLeftMarker")
    marker["laneMarker"].update(a0=1.8, a1=0.01, a2=0.001, a3=0.0, startRange=0.0,
                                endRange=40.0)
    marker["laneMarkerType"] = 1


def _sign(values: dict[str, Any]) -> None:
    _first(values, "trafficSigns").update(signLongPosition=30.0, signLatPosition=2.0,
                                          signHeight=1.0, signType=1)
    _set_count(values, "numberTrafficSigns", 1)


def _spot(values: dict[str, Any]) -> None:
    _first(values, "activeLightSpots").update(longPos=40, leftAngle=-0.06, rightAngle=-0.04,
                                              id=9, classification=3)
    _set_count(values, "numOfActiveLightSpots", 1)


def _entity(update: Any, eid: str) -> Any:
    return next(e for e in update.entities if e.id == eid)


def test_known_values_land_where_a_hand_computation_says() -> None:
    codec = MessageCodec(None)
    sink = ListSink()
    feed = Feed(codec, sink)
    for t, (name, edit) in enumerate(((OBSTACLES, _obstacle), (ROAD, _road), (SIGNS, _sign),
                                      (LIGHTS, _spot)), 1):
        feed.message(name, _wire(codec, name, edit), float(t))
    [obstacles] = sink.decoded("/scene/obstacles")
    box = _entity(obstacles, "obstacle/3")
    assert box.frame_id == "vehicle"
    cube = box.cubes[0]
    # latDistance is left positive (C5); the distances name the middle of the rear corners,
    # the box reaches 4 m forward along the 0.1 rad heading: centre 2 m along it
    assert cube.pose.position.x == pytest.approx(20.0 + 2.0 * math.cos(0.1), abs=1e-5)
    assert cube.pose.position.y == pytest.approx(3.0 + 2.0 * math.sin(0.1), abs=1e-5)
    assert cube.pose.position.z == pytest.approx(0.8, abs=1e-5)  # standing on the road
    assert cube.pose.orientation.z == pytest.approx(math.sin(0.05), abs=1e-6)
    assert cube.pose.orientation.w == pytest.approx(math.cos(0.05), abs=1e-6)
    assert (cube.size.x, cube.size.y) == pytest.approx((4.0, 2.0))
    assert box.texts[0].text.startswith("CIPV 3 ") and box.lines  # the CIPV's ring
    assert {kv.key: kv.value for kv in box.metadata}["cipv"] == "True"
    [lanes] = sink.decoded("/scene/lanes")
    points = _entity(lanes, "line/hostLeftMarker").lines[0].points
    assert (points[0].x, points[0].y) == pytest.approx((0.0, 1.8), abs=1e-5)
    assert (points[-1].x, points[-1].y) == pytest.approx((40.0, 1.8 + 0.4 + 1.6), abs=1e-4)
    [signs] = sink.decoded("/scene/signs")
    plate = _entity(signs, "sign/0").cubes[0].pose.position
    # signLatPosition is right positive (§12.2): 2 m to the right is y = -2; its height is
    # relative to the sensor, which is CAMERA_HEIGHT_M above the road
    assert (plate.x, plate.y, plate.z) == pytest.approx((30.0, -2.0, CAMERA_HEIGHT_M + 1.0))
    [lights] = sink.decoded("/scene/lights")
    lamp = _entity(lights, "light/9").spheres[0].pose.position
    # the middle of the border angles, -0.05 rad right positive, is 0.05 rad to the left
    assert (lamp.x, lamp.y) == pytest.approx((40.0, 40.0 * math.tan(0.05)), abs=1e-5)
    transforms = sink.decoded("/tf")
    assert {(tf.parent_frame_id, tf.child_frame_id) for tf in transforms} == {
        ("vehicle", "camera")}  # no speed yet: no odometry
    assert transforms[0].translation.z == pytest.approx(CAMERA_HEIGHT_M)


def test_an_object_that_leaves_is_deleted_and_unknown_signs_are_not_drawn() -> None:
    codec = MessageCodec(None)
    sink = ListSink()
    feed = Feed(codec, sink)
    feed.message(OBSTACLES, _wire(codec, OBSTACLES, _obstacle), 1.0)
    feed.message(OBSTACLES, _wire(codec, OBSTACLES, lambda values: None), 2.0)
    first, second = sink.decoded("/scene/obstacles")
    assert not first.deletions
    assert [d.id for d in second.deletions] == ["obstacle/3"]
    assert [e.id for e in second.entities] == ["ego"]

    def unknown(values: dict[str, Any]) -> None:
        _sign(values)
        _first(values, "trafficSigns").update(signLongPosition=127.0)  # §12.2: unknown

    feed.message(SIGNS, _wire(codec, SIGNS, unknown), 3.0)
    [signs] = sink.decoded("/scene/signs")
    assert not signs.entities


def test_ego_speed_and_yaw_rate_move_the_vehicle_in_odom() -> None:
    codec = MessageCodec(None)
    sink = ListSink()
    feed = Feed(codec, sink)
    for k in range(11):  # 10 m/s, turning left at 0.1 rad/s, for 1 s
        feed.ego(10.0, 0.1, k * 0.1)
    feed.message(OBSTACLES, _wire(codec, OBSTACLES, _obstacle), 1.0)
    odom = next(tf for tf in sink.decoded("/tf") if tf.parent_frame_id == "odom")
    assert odom.child_frame_id == "vehicle"
    assert odom.translation.x == pytest.approx(10.0 * math.sin(0.1) / 0.1, rel=0.02)
    assert odom.translation.y > 0.0  # turned left: y is left positive
    assert 2 * math.atan2(odom.rotation.z, odom.rotation.w) == pytest.approx(0.1)


def _read(path: Path) -> tuple[dict[str, int], dict[str, Any], list[Any]]:
    from mcap.reader import make_reader

    counts: dict[str, int] = {}
    schemas: dict[str, Any] = {}
    decoded = []
    with path.open("rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            schemas[channel.topic] = schema
            if channel.topic == "/scene/obstacles":
                decode = message_class(schema.name, schema.data)
                decoded.append(decode.FromString(message.data))
    return counts, schemas, decoded


def test_export_mcap_writes_the_scene_beside_its_topics(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("mcap", reason="the [export] extra (mcap) is not installed")
    cap, out = tmp_path / "demo.pcapng", tmp_path / "demo.mcap"
    assert main(["demo", "--virtual-time", "--duration", "2", "--capture", str(cap),
                 "--json"]) == 0
    capsys.readouterr()
    assert main(["dissect", str(cap), "--stats", "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert main(["export", str(cap), "--mcap", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {tmp_path / 'demo.layout.json'}" in printed
    counts, schemas, obstacles = _read(out)
    messages = stats["messages"]
    for name, topic in (("EYEQ_VIS_OBSTACLES_MSG", "/scene/obstacles"),
                        ("EYEQ_VIS_ROAD_DATA_MSG", "/scene/lanes"),
                        ("EYEQ_VIS_TRAFFIC_SIGNS_MSG", "/scene/signs"),
                        ("EYEQ_VIS_LIGHT_SENSOR_DATA_MSG", "/scene/lights")):
        assert counts[topic] == messages[name]["count"] == counts[f"/eyeq/e2h/{name}"]
    assert counts["/ego"] == messages["HOST_VEH_STATE_MSG"]["count"]
    assert counts["/log"] == sum(stats["events"].values()) + stats["message_errors"]
    assert counts["/tf"] == 2 * counts["/scene/obstacles"]  # camera, and odometry
    # the schemas in the file are the SDK's own
    for topic, cls in (("/scene/obstacles", fgm.SceneUpdate), ("/tf", fgm.FrameTransform),
                       ("/log", fgm.Log)):
        sdk = cls.get_schema()
        assert (schemas[topic].name, schemas[topic].encoding) == (sdk.name, "protobuf")
        assert schemas[topic].data == sdk.data
    last = obstacles[-1]
    assert any(e.id.startswith("obstacle/") for e in last.entities)
    assert all(e.frame_id == "vehicle" for e in last.entities)
    layout = json.loads((tmp_path / "demo.layout.json").read_text())
    text = json.dumps(layout)
    assert '"panelType": "ThreeDee"' in text and '"panelType": "Log"' in text
    assert text.count('"panelType": "Plot"') == 3
    assert all(topic in text for topic in ("/scene/obstacles", "/ego.speed", "/log"))


def test_a_live_host_is_published_at_most_once_per_dasp_period_and_kind() -> None:
    from eyeq_spi import emulator
    from eyeq_spi.foxglove.live import HostFeed

    emu = emulator.build()
    sink = ListSink()
    live = HostFeed(emu.host, sink)
    emu.run_for(3.0)  # virtual time: the same schedule on any machine
    times: dict[str, list[int]] = {}
    for topic, _, _, t in sink.got:
        times.setdefault(topic, []).append(t)
    running = next(t.time for t in emu.host.transitions if t.dst.value == "RUNNING_VISION")
    for topic in ("/scene/obstacles", "/scene/lanes", "/scene/signs", "/scene/lights"):
        stamps = times[topic]
        gaps = [b - a for a, b in itertools.pairwise(stamps)]
        assert min(gaps) >= 1e9 / 18 - 1, topic  # never faster than the DASP rate
        # and not slower: every message of the stream since Running Vision, give or take one
        assert len(stamps) >= (3.0 - running) * 18 - 2, (topic, len(stamps))
    log = message_class("foxglove.Log", fgm.Log.get_schema().data)
    lines = [log.FromString(data).message for topic, _, data, _ in sink.got if topic == "/log"]
    assert any("--RUNNING_VISION--> RUNNING_VISION" in line for line in lines), lines
    assert times["/ego"] and times["/streams"] and times["/link/ack_latency"]
    assert "scene updates" in live.describe()


def test_foxglove_option_errors_are_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from eyeq_spi.foxglove.server import ServerSink

    assert main(["demo", "--virtual-time", "--foxglove", "localhost:port"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "HOST:PORT" in err
    taken = ServerSink("127.0.0.1:0")
    try:
        assert main(["demo", "--virtual-time", "--duration", "0.1", "--foxglove",
                     f"127.0.0.1:{taken.port}"]) == 2
    finally:
        taken.close()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot serve there" in err, err


def test_the_layout_in_docs_is_the_one_export_writes() -> None:
    from eyeq_spi.foxglove.layout import layout_json

    docs = Path(__file__).resolve().parents[1] / "docs" / "foxglove.layout.json"
    assert docs.read_text(encoding="utf-8") == layout_json() + "\n", (
        "regenerate it: python -c 'from eyeq_spi.foxglove.layout import layout_json; "
        "print(layout_json())' > docs/foxglove.layout.json")
