"""A :class:`~eyeq_spi.plot.perceived.Scene` as ``foxglove.SceneUpdate`` messages, one per DASP
message kind, in the vehicle frame of :mod:`eyeq_spi.plot.vehicle_frame`. Every object, line,
sign and spot is an entity of its own; an entity a message no longer carries is deleted by the
next update of its kind, and each lives three periods of its stream. The colours are the
bird's-eye picture's.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from eyeq_spi.errors import MissingExtra
from eyeq_spi.foxglove.topics import WORLD_FRAME
from eyeq_spi.plot import birdseye
from eyeq_spi.plot.perceived import LIGHTS, OBSTACLES, ROAD, SIGNS, Scene, SceneLine
from eyeq_spi.plot.vehicle_frame import (
    CAMERA_FRAME,
    CAMERA_HEIGHT_M,
    FRAME,
    above_road,
    box_centre,
    yaw_quaternion,
)

KINDS = (OBSTACLES, ROAD, SIGNS, LIGHTS)
LIFETIME_PERIODS = 3.0  # an entity outlives its message by this many nominal periods
DEFAULT_RATE_HZ = 18.0  # the scene streams' nominal rate (seed 004's message table)
LINE_STEP_M = 2.0  # a lane line is sampled every 2 m over its view range
LINE_POINTS_MAX = 60
LINE_WIDTH_M = 0.15
OBJECT_HEIGHT_M = 1.5  # drawn for an object whose height is not reported
SIGN_SIZE_M = 0.7
SPOT_RADIUS_M = 0.3
SPOT_HEIGHT_M = 0.7  # lamps' height above the road (the EyeQ gives angles and a range)
LABEL_SIZE = 14.0  # pixels (scale-invariant labels)
SPOT_COLOURS = {"head": "#fff6c0", "tail": "#ff2020"}


def fg() -> Any:
    """``foxglove.messages``: the SDK's schemas (the ``foxglove`` extra)."""
    try:
        import foxglove.messages as messages
    except ImportError:
        raise MissingExtra("foxglove", "the Foxglove scene") from None
    return messages


def colour(hex_rgb: str, alpha: float = 1.0) -> Any:
    value = int(hex_rgb.lstrip("#"), 16)
    return fg().Color(r=(value >> 16) / 255.0, g=((value >> 8) & 0xFF) / 255.0,
                      b=(value & 0xFF) / 255.0, a=alpha)


def timestamp(ns: int) -> Any:
    return fg().Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def pose(x: float, y: float, z: float, yaw: float = 0.0) -> Any:
    sdk = fg()
    qx, qy, qz, qw = yaw_quaternion(yaw)
    return sdk.Pose(position=sdk.Vector3(x=x, y=y, z=z),
                    orientation=sdk.Quaternion(x=qx, y=qy, z=qz, w=qw))


def _text(text: str, x: float, y: float, z: float) -> Any:
    sdk = fg()
    return sdk.TextPrimitive(pose=pose(x, y, z), billboard=True, font_size=LABEL_SIZE,
                             scale_invariant=True, color=colour("#000000"), text=text)


def _meta(**values: Any) -> list[Any]:
    return [fg().KeyValuePair(key=k, value=str(v)) for k, v in values.items()]


class SceneMessages:
    """Builds each kind's SceneUpdate and remembers what it showed (to delete what is gone)."""

    def __init__(self, rates_hz: dict[str, float] | None = None,
                 camera_height: float = CAMERA_HEIGHT_M) -> None:
        self.rates = rates_hz or {}
        self.camera_height = camera_height
        self.shown: dict[str, set[str]] = {kind: set() for kind in KINDS}

    def update(self, kind: str, scene: Scene, ns: int) -> Any:
        """The SceneUpdate of ``kind`` (one of :data:`KINDS`) for ``scene`` at ``ns``."""
        sdk = fg()
        stamp = timestamp(ns)
        period = 1.0 / (self.rates.get(kind) or DEFAULT_RATE_HZ)
        lifetime = sdk.Duration.from_secs(LIFETIME_PERIODS * period)
        build = {OBSTACLES: self._obstacles, ROAD: self._lanes, SIGNS: self._signs,
                 LIGHTS: self._lights}[kind]
        parts = list(build(scene))
        entities = [sdk.SceneEntity(timestamp=stamp, frame_id=FRAME, id=eid, lifetime=lifetime,
                                    **primitives) for eid, primitives in parts]
        ids = {eid for eid, _ in parts}
        gone = sorted(self.shown[kind] - ids)
        self.shown[kind] = ids
        matching = sdk.SceneEntityDeletionType.MatchingId
        deletions = [sdk.SceneEntityDeletion(timestamp=stamp, type=matching, id=eid)
                     for eid in gone]
        return sdk.SceneUpdate(deletions=deletions, entities=entities)

    def _obstacles(self, scene: Scene) -> Iterable[tuple[str, dict[str, Any]]]:
        sdk = fg()
        ego_length, ego_width = birdseye.EGO
        yield "ego", {"cubes": [sdk.CubePrimitive(
            pose=pose(-ego_length / 2.0, 0.0, OBJECT_HEIGHT_M / 2.0), size=sdk.Vector3(
                x=ego_length, y=ego_width, z=OBJECT_HEIGHT_M), color=colour("#404040", 0.6))]}
        for obstacle in scene.objects:
            x, y = box_centre(obstacle.long, obstacle.lat, obstacle.length, obstacle.heading)
            height = obstacle.height or OBJECT_HEIGHT_M
            length, width = max(obstacle.length, 0.3), max(obstacle.width, 0.3)
            size = sdk.Vector3(x=length, y=width, z=height)
            cubes = [sdk.CubePrimitive(pose=pose(x, y, height / 2.0, obstacle.heading), size=size,
                                       color=colour(birdseye.class_colour(obstacle.cls), 0.8))]
            label = (f"{obstacle.id} {obstacle.cls_name} "
                     f"{math.hypot(obstacle.long, obstacle.lat):.1f} m")
            lines = []
            if obstacle.cipv:
                label = f"CIPV {label}"
                lines.append(self._ring(x, y, obstacle.heading, length + 0.6, width + 0.6))
            ttc = obstacle.closing_ttc
            yield f"obstacle/{obstacle.id}", {
                "cubes": cubes, "lines": lines,
                "texts": [_text(label, x, y, height + 0.6)],
                "metadata": _meta(id=obstacle.id, classification=obstacle.cls_name,
                                  long_m=round(obstacle.long, 2), lat_m=round(obstacle.lat, 2),
                                  heading_rad=round(obstacle.heading, 3),
                                  v_long=round(obstacle.v_long, 2), v_lat=round(obstacle.v_lat, 2),
                                  cipv=obstacle.cipv, ttc_s="-" if ttc is None else round(ttc, 2))}

    def _ring(self, x: float, y: float, yaw: float, length: float, width: float) -> Any:
        """The CIPV's mark: a loop on the road around its box."""
        sdk = fg()
        corners = [(length / 2, width / 2), (-length / 2, width / 2), (-length / 2, -width / 2),
                   (length / 2, -width / 2)]
        return sdk.LinePrimitive(
            type=sdk.LinePrimitiveLineType.LineLoop, pose=pose(x, y, 0.05, yaw), thickness=0.2,
            points=[sdk.Point3(x=a, y=b, z=0.0) for a, b in corners],
            color=colour(birdseye.CIPV_EDGE))

    def _lanes(self, scene: Scene) -> Iterable[tuple[str, dict[str, Any]]]:
        for line in scene.lines:
            yield f"line/{line.name}", {
                "lines": [line_strip(line)],
                "metadata": _meta(name=line.name, kind=line.kind, type=line.type_name or "-",
                                  a0=line.coeffs[0], a1=line.coeffs[1], a2=line.coeffs[2],
                                  a3=line.coeffs[3], start_m=line.start, end_m=line.end)}

    def _signs(self, scene: Scene) -> Iterable[tuple[str, dict[str, Any]]]:
        sdk = fg()
        for index, sign in enumerate(scene.signs):
            if not sign.known:
                continue
            x, y, z = sign.long, sign.lat, above_road(sign.height, self.camera_height)
            yield f"sign/{index}", {
                "cubes": [sdk.CubePrimitive(pose=pose(x, y, z), size=sdk.Vector3(
                    x=0.05, y=SIGN_SIZE_M, z=SIGN_SIZE_M), color=colour(birdseye.SIGN_COLOUR))],
                "texts": [_text(sign.name, x, y, z + SIGN_SIZE_M)],
                "metadata": _meta(type=sign.type, name=sign.name, long_m=round(x, 2),
                                  lat_m=round(y, 2), height_m=round(sign.height, 2))}

    def _lights(self, scene: Scene) -> Iterable[tuple[str, dict[str, Any]]]:
        sdk = fg()
        for spot in scene.spots:
            head = "head" in spot.cls_name.lower()
            size = sdk.Vector3(x=2 * SPOT_RADIUS_M, y=2 * SPOT_RADIUS_M, z=2 * SPOT_RADIUS_M)
            yield f"light/{spot.id}", {
                "spheres": [sdk.SpherePrimitive(
                    pose=pose(spot.long, spot.lat, SPOT_HEIGHT_M), size=size,
                    color=colour(SPOT_COLOURS["head" if head else "tail"]))],
                "metadata": _meta(id=spot.id, classification=spot.cls_name,
                                  long_m=round(spot.long, 2), lat_m=round(spot.lat, 2))}


def line_points(line: SceneLine) -> list[tuple[float, float]]:
    """(x, y) along a line's polynomial over its view range, every LINE_STEP_M at most."""
    span = line.end - line.start
    count = max(2, min(LINE_POINTS_MAX, math.ceil(span / LINE_STEP_M) + 1))
    xs = [line.start + span * k / (count - 1) for k in range(count)]
    return [(x, line.lateral(x)) for x in xs]


def line_strip(line: SceneLine) -> Any:
    sdk = fg()
    return sdk.LinePrimitive(
        type=sdk.LinePrimitiveLineType.LineStrip, pose=pose(0.0, 0.0, 0.02),
        thickness=LINE_WIDTH_M, points=[sdk.Point3(x=x, y=y, z=0.0) for x, y in line_points(line)],
        color=colour(birdseye.LINE_COLOURS[line.kind]))


def frame_transforms(ns: int, odom: tuple[float, float, float] | None,
                     camera_height: float = CAMERA_HEIGHT_M) -> list[Any]:
    """``vehicle`` -> ``camera`` (the sensor above the frame's origin) and, when the vehicle's
    dead-reckoned pose (x, y, yaw) is known, ``odom`` -> ``vehicle``."""
    sdk = fg()
    stamp = timestamp(ns)
    unit = sdk.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
    out = [sdk.FrameTransform(timestamp=stamp, parent_frame_id=FRAME, child_frame_id=CAMERA_FRAME,
                              translation=sdk.Vector3(x=0.0, y=0.0, z=camera_height),
                              rotation=unit)]
    if odom is not None:
        x, y, yaw = odom
        qx, qy, qz, qw = yaw_quaternion(yaw)
        out.append(sdk.FrameTransform(
            timestamp=stamp, parent_frame_id=WORLD_FRAME, child_frame_id=FRAME,
            translation=sdk.Vector3(x=x, y=y, z=0.0), rotation=sdk.Quaternion(x=qx, y=qy, z=qz,
                                                                              w=qw)))
    return out
