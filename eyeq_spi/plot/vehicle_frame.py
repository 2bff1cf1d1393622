"""The EyeQ's vehicle frame, stated once: every view of the scene (the bird's-eye picture, the
monitor, the Foxglove scene) reads positions through this module.

The frame is ISO 8855: ``x`` forward, ``y`` to the left, ``z`` up, angles counter-clockwise
(to the left) positive, in metres and radians. Its origin is the point on the road below the
camera: seed 004 measures every distance from the sensor ("distance estimation from detected
sign to sensor", §12.2; an object's distances to "the middle of the Rear Left and Rear Right
corners", §13.2.5.3), and heights from the sensor too (``signHeight``, "relative to the
sensor"), so a height becomes ``z`` by adding the camera's height above the road.

Signs (decision C5, ``docs/PROTOCOL_DECISIONS.md``): the EyeQ4's object ``latDistance`` and the
lane polynomials' ``a0`` are left positive already (ISO 8855) and pass through unchanged. Seed
004 prints the opposite sign for two members, and only those are turned here:
``signLatPosition`` ("a negative value indicates the sign is on the left", §12.2) and the light
spots' angles ("angles to the right of the sensor coordinate system are positive", §11.2).
The DASP scene members are in radians already (``heading``, the light spots' angles).
"""

from __future__ import annotations

import math

FRAME = "vehicle"  # the frame every scene position is given in
CAMERA_FRAME = "camera"  # the sensor: (0, 0, camera height) in FRAME, no rotation
CAMERA_HEIGHT_M = 1.3  # above the road, when the run does not say (the simulated EyeQ's)
RIGHT_POSITIVE = -1.0  # a right-positive lateral or angle times this is left positive (C5)
SIGN_LONG_UNKNOWN = 127.0  # §12.2 signLongPosition: "Set to 127 when the distance is unknown"
SIGN_LAT_UNKNOWN = -128.0  # §12.2 signLatPosition: "Set to -128 when the distance is unknown"


def left_positive(right_positive: float) -> float:
    """A lateral distance or angle the seed gives right positive, in the frame (C5)."""
    return RIGHT_POSITIVE * right_positive


def sign_known(long: float, lat: float) -> bool:
    """False when ``signLongPosition``/``signLatPosition`` (as on the wire) say the EyeQ does not
    know the sign's distance (§12.2)."""
    return long < SIGN_LONG_UNKNOWN and lat > SIGN_LAT_UNKNOWN


def above_road(height: float, camera_height: float = CAMERA_HEIGHT_M) -> float:
    """``z`` of a height the seed gives relative to the sensor (``signHeight``)."""
    return camera_height + height


def light_spot_position(long: float, left_angle: float, right_angle: float) -> tuple[float, float]:
    """A light spot's (x, y): ``longPos`` ahead, on the ray through the middle of its left and
    right border angles (right positive, §11.2)."""
    middle = left_positive((left_angle + right_angle) / 2.0)
    return long, long * math.tan(middle)


def box_centre(long: float, lat: float, length: float, heading: float) -> tuple[float, float]:
    """The (x, y) centre of an object's box: ``longDistance``/``latDistance`` name the middle of
    its rear corners, and the box extends ``length`` forward along its ``heading``."""
    return long + math.cos(heading) * length / 2.0, lat + math.sin(heading) * length / 2.0


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` radians about z (left positive)."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)
