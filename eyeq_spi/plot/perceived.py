"""Decoded DASP fields -> the scene: objects, lane/border polynomials and traffic signs.

Pure data, no plotting library: the bird's-eye plot and the live monitor both read the scene
from here, and both get their fields from the same decoder as ``eyeq-spi dissect``.

Coordinates are the vehicle frame of :mod:`eyeq_spi.plot.vehicle_frame` (``long`` forward,
``lat`` to the left: the host's left lane marker has a positive ``a0``, §10), which also turns
the members the seed gives right positive. Structures are found by their members, not by a path
written per SW version, so every release's variant of a message works:

- an object is an element of an array of structs with ``physicalState`` (§13.2.5); it is valid
  when ``id`` is in 1..E_EYEQ_MAX_VISION_OBJECTS ("any other value means invalid object");
- a line is any ``eyeq_polynomial_model_t`` (members ``a0..a3``, ``startRange``, ``endRange``,
  ``y = a0 + a1*x + a2*x^2 + a3*x^3``, §10.4); it is drawn over ``[startRange, endRange]`` and
  skipped when that range is empty (the sim and the seed's defaults send zeros for "none") or
  its type is INVALID;
- signs are the first ``numberTrafficSigns`` elements of ``trafficSigns`` (§12);
- light spots are the first ``numOfActiveLightSpots`` elements of ``activeLightSpots`` (§11).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.catalog.messages import EnumDef
from eyeq_spi.codec.layout import Layout
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.plot import vehicle_frame

OBSTACLES = "EYEQ_VIS_OBSTACLES_MSG"
ROAD = "EYEQ_VIS_ROAD_DATA_MSG"
SIGNS = "EYEQ_VIS_TRAFFIC_SIGNS_MSG"
LIGHTS = "EYEQ_VIS_LIGHT_SENSOR_DATA_MSG"
SCENE_MESSAGES = (OBSTACLES, ROAD, SIGNS, LIGHTS)
POLY_KEYS = frozenset(("a0", "a1", "a2", "a3", "startRange", "endRange"))
CIPV = "CIPV"  # object_is_cipv value name (§13.2.5)
TTC_NONE = 7.0  # §13.2.2 ttc_const_vel: "Set to 7 seconds if no valid TTC value"
NO_TTC = "\u2014"  # what the views show for an object without a time to collision


@dataclass(frozen=True)
class SceneObject:
    id: int
    cls: int
    cls_name: str
    long: float  # to the middle of the rear corners (§13.2.5.3)
    lat: float
    width: float
    length: float
    heading: float  # radians, relative to the host's heading
    v_long: float  # absolute velocity, m/s
    v_lat: float
    cipv: bool
    ttc: float | None  # ttc_const_vel (SW5 and later)
    height: float = 0.0  # 0: not reported

    @property
    def closing_ttc(self) -> float | None:
        """The time to collision worth showing: only for an object ahead of the car
        (``longDistance`` > 0) that the EyeQ reports as closing, a ``ttc_const_vel`` below its
        top of range (TTC_NONE, 7 s, is "none"); else None."""
        ttc = self.ttc
        if ttc is None or not 0.0 <= ttc < TTC_NONE or self.long <= 0.0:
            return None
        return ttc


@dataclass(frozen=True)
class SceneLine:
    name: str  # hostLeftMarker, leftRoadBorder, laneCenter, ...
    kind: str  # "marker" | "border" | "centre"
    coeffs: tuple[float, float, float, float]
    start: float
    end: float
    type_name: str | None

    def lateral(self, x: float) -> float:
        a0, a1, a2, a3 = self.coeffs
        return a0 + a1 * x + a2 * x * x + a3 * x * x * x


@dataclass(frozen=True)
class SceneSign:
    long: float
    lat: float  # left positive (C5: signLatPosition is right positive on the wire)
    height: float  # relative to the sensor
    type: int
    name: str
    known: bool = True  # False: the EyeQ does not know where it is (§12.2)


@dataclass(frozen=True)
class SceneSpot:
    """An active light spot (§11.2) at its position in the vehicle frame."""

    id: int
    long: float
    lat: float
    cls: int
    cls_name: str


@dataclass
class Scene:
    time: float | None = None
    objects: list[SceneObject] = field(default_factory=list)
    lines: list[SceneLine] = field(default_factory=list)
    signs: list[SceneSign] = field(default_factory=list)
    spots: list[SceneSpot] = field(default_factory=list)
    times: dict[str, float | None] = field(default_factory=dict)  # message -> its time


class Labels:
    """Enum value names of decoded members, looked up through the message's layout (specs/)."""

    def __init__(self, codec: MessageCodec) -> None:
        self.codec = codec
        self._enums: dict[tuple[str, tuple[str, ...]], EnumDef | None] = {}
        self.max_objects = _constant(codec, "E_EYEQ_MAX_VISION_OBJECTS", 15)

    def enum(self, message: str, path: tuple[str, ...]) -> EnumDef | None:
        key = (message, path)
        if key not in self._enums:
            self._enums[key] = self._find(message, path)
        return self._enums[key]

    def _find(self, message: str, path: tuple[str, ...]) -> EnumDef | None:
        try:
            lay: Layout = self.codec.layout(self.codec.message(message))
        except Exception:
            return None
        for name in path[:-1]:
            child = lay.children.get(name)
            if child is None:
                return None
            lay = child
        try:
            member = lay.field(path[-1]).member
        except Exception:
            return None
        return self.codec.cat.enums.get(member.enum or "")

    def label(self, message: str, path: tuple[str, ...], value: Any) -> str:
        enum = self.enum(message, path)
        if enum is None or not isinstance(value, int):
            return str(value)
        entry = enum.values.get(value)
        if entry is None:
            return f"{value}?"
        return entry.semantic or entry.name


def _constant(codec: MessageCodec, name: str, default: int) -> int:
    try:
        return int(codec.cat.constant(name, codec.sw))
    except Exception:
        return default


def walk(value: Any, path: tuple[str, ...] = ()
          ) -> Iterator[tuple[tuple[str, ...], dict[str, Any]]]:
    """Every dict in a decoded value with its path of member names (array indices dropped)."""
    if isinstance(value, dict):
        yield path, value
        for key, member in value.items():
            if isinstance(member, dict | list):
                yield from walk(member, (*path, key))
    elif isinstance(value, list):
        for member in value:
            if isinstance(member, dict):
                yield from walk(member, path)


def _f(fields: dict[str, Any], key: str, default: float = 0.0) -> float:
    value = fields.get(key, default)
    return float(value) if isinstance(value, int | float) else default


def objects(fields: dict[str, Any], labels: Labels) -> list[SceneObject]:
    out: list[SceneObject] = []
    for path, struct in walk(fields):
        ps = struct.get("physicalState")
        if not isinstance(ps, dict) or "id" not in struct:
            continue
        oid = struct["id"]
        if not isinstance(oid, int) or not 1 <= oid <= labels.max_objects:
            continue
        cls = int(struct.get("classification", 0))
        cipv = labels.label(OBSTACLES, (*path, "isCipv"), struct.get("isCipv", 0)) == CIPV
        ttc = struct.get("ttc_const_vel")
        out.append(SceneObject(
            id=oid, cls=cls, cls_name=labels.label(OBSTACLES, (*path, "classification"), cls),
            long=_f(ps, "longDistance"), lat=_f(ps, "latDistance"), width=_f(ps, "width"),
            length=_f(ps, "length"), heading=_f(ps, "heading"), height=_f(ps, "height"),
            v_long=_f(ps, "absoluteLongVelocity"), v_lat=_f(ps, "absoluteLatVelocity"),
            cipv=cipv, ttc=float(ttc) if isinstance(ttc, int | float) else None))
    return out


def _line_kind(name: str) -> str:
    if "Border" in name:
        return "border"
    if "Center" in name or "Centre" in name:
        return "centre"
    return "marker"


def lines(fields: dict[str, Any], labels: Labels) -> list[SceneLine]:
    out: list[SceneLine] = []
    parents: dict[tuple[str, ...], dict[str, Any]] = {}
    for path, struct in walk(fields):
        parents[path] = struct
        if not struct.keys() >= POLY_KEYS:
            continue
        start, end = _f(struct, "startRange"), _f(struct, "endRange")
        if not end > start:
            continue
        parent = parents.get(path[:-1], {})
        own = path[-1] if path else "line"
        # hostLeftMarker.laneMarker -> hostLeftMarker; roadHppFusionInfo.laneCenter -> laneCenter
        name = path[-2] if len(path) >= 2 and own in ("laneMarker", "roadBorder") else own
        type_name = None
        for key, value in parent.items():
            if key.endswith(("MarkerType", "BorderType")) and isinstance(value, int):
                type_name = labels.label(ROAD, (*path[:-1], key), value)
                break
        if type_name in ("INVALID", "Invalid"):
            continue  # lane_marker_type 6, road_border_type 1 (SW7+)
        out.append(SceneLine(
            name=name, kind=_line_kind(name),
            coeffs=(_f(struct, "a0"), _f(struct, "a1"), _f(struct, "a2"), _f(struct, "a3")),
            start=start, end=end, type_name=type_name))
    return out


def _active(fields: dict[str, Any], array: str, count: str
            ) -> Iterator[tuple[tuple[str, ...], dict[str, Any]]]:
    """(path, element) of the first ``count`` elements of every ``array`` (the whole array when
    the count is missing): signs and light spots."""
    for path, struct in walk(fields):
        elems = struct.get(array)
        if not isinstance(elems, list):
            continue
        declared = struct.get(count)
        for elem in elems[:max(0, int(declared) if isinstance(declared, int) else len(elems))]:
            if isinstance(elem, dict):
                yield path, elem


def signs(fields: dict[str, Any], labels: Labels) -> list[SceneSign]:
    out: list[SceneSign] = []
    for path, sign in _active(fields, "trafficSigns", "numberTrafficSigns"):
        st = int(sign.get("signType", 0))
        long, lat = _f(sign, "signLongPosition"), _f(sign, "signLatPosition")
        out.append(SceneSign(
            long=long, lat=vehicle_frame.left_positive(lat),
            known=vehicle_frame.sign_known(long, lat),
            height=_f(sign, "signHeight"), type=st,
            name=labels.label(SIGNS, (*path, "trafficSigns", "signType"), st)))
    return out


def spots(fields: dict[str, Any], labels: Labels) -> list[SceneSpot]:
    out: list[SceneSpot] = []
    for path, spot in _active(fields, "activeLightSpots", "numOfActiveLightSpots"):
        x, y = vehicle_frame.light_spot_position(
            _f(spot, "longPos"), _f(spot, "leftAngle"), _f(spot, "rightAngle"))
        cls = int(spot.get("classification", 0))
        oid = spot.get("id", 0)
        out.append(SceneSpot(
            id=int(oid) if isinstance(oid, int) else 0, long=x, lat=y, cls=cls,
            cls_name=labels.label(LIGHTS, (*path, "activeLightSpots", "classification"), cls)))
    return out


class SceneTracker:
    """The latest scene: feed it decoded messages (name, fields, time) in any order."""

    def __init__(self, labels: Labels) -> None:
        self.labels = labels
        self.scene = Scene()

    def update(self, name: str | None, fields: dict[str, Any] | None, time_s: float | None,
               errors: list[str] | tuple[str, ...] = ()) -> bool:
        """True when the message changed the scene. A message with decode errors is skipped,
        as the host skips it (D5); E2E and counter errors alone do not hide it from a view."""
        if name not in SCENE_MESSAGES or not fields:
            return False
        if any(not (e.startswith("E2E") or e.startswith("DASP counter")) for e in errors):
            return False
        sc = self.scene
        if name == OBSTACLES:
            sc.objects = objects(fields, self.labels)
        elif name == ROAD:
            sc.lines = lines(fields, self.labels)
        elif name == SIGNS:
            sc.signs = signs(fields, self.labels)
        else:
            sc.spots = spots(fields, self.labels)
        sc.times[name] = time_s
        sc.time = time_s
        return True

    def snapshot(self) -> Scene:
        sc = self.scene
        return Scene(sc.time, list(sc.objects), list(sc.lines), list(sc.signs), list(sc.spots),
                     dict(sc.times))
