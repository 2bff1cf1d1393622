"""How the scene writes into payloads of any SW version: the shape of a value dict identifies
the layout variant (every release with that shape), and each value is clamped into the member's
declared range and wire type (split out of :mod:`eyeq_spi.sim.scene`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from eyeq_spi.catalog.messages import Catalog, Member, SwKey, catalog
from eyeq_spi.codec.layout import INT_RANGE
from eyeq_spi.errors import SpecError
from eyeq_spi.sim.dasp_fast import StructView

FArr = npt.NDArray[np.float64]
IArr = npt.NDArray[np.int64]

FRAME_RATE = 18.0  # §7.1.4: every vision message runs at 18 Hz
LANE_WIDTH = 3.6
HALF_LANE = LANE_WIDTH / 2
CAM_HEIGHT = 1.3  # m above the road
FOCAL_PX = 1000.0
IMAGE_W, IMAGE_H = 1824, 960  # pixel ranges of eyeq_traffic_sign_t
MAX_SUBSTEP = 0.1  # s; longer steps are integrated in pieces
MAX_GAP = 30.0  # s; of a longer pause between steps only the last 30 s are simulated
TTC_NONE = 7.0  # §13.2.2 ttc_const_vel: "Set to 7 seconds if no valid TTC value"
EGO_LENGTH = 4.5
EGO_SPEED_MIN, EGO_SPEED_MAX = -20.0, 100.0  # m/s, §7.1.2.2 vehicleVelocity range
MAX_OBJECTS = 15  # E_EYEQ_MAX_VISION_OBJECTS
MAX_SIGNS = 20  # eyeq_traffic_sign_info_t.trafficSigns
MAX_SPOTS = 15  # eyeq_active_light_sensor_info_t.activeLightSpots

VEHICLE, ONCOMING, CYCLIST, PEDESTRIAN = 0, 1, 2, 3
# object_classification name, spawn weight, width, length, height, kind
CLASSES: tuple[tuple[str, float, float, float, float, int], ...] = (
    ("car", 0.58, 1.82, 4.6, 1.50, VEHICLE),
    ("truck", 0.14, 2.50, 12.0, 3.60, VEHICLE),
    ("bike", 0.04, 0.80, 2.2, 1.40, VEHICLE),
    ("uncertain_vehicle", 0.03, 1.90, 4.8, 1.60, VEHICLE),
    ("bicycle", 0.08, 0.60, 1.8, 1.70, CYCLIST),
    ("pedestrian", 0.13, 0.60, 0.6, 1.75, PEDESTRIAN),
)
CLASS_DEFAULT = {"car": 0, "truck": 1, "bike": 2, "bicycle": 3, "pedestrian": 4,
                  "uncertain_vehicle": 7}
# traffic_sign names and weights: mostly speed limits (§ traffic_sign enum, SLI_Explicit)
SIGNS: tuple[tuple[str, float], ...] = (
    ("e_std_60", 0.05), ("e_std_80", 0.16), ("e_std_100", 0.17), ("e_std_120", 0.14),
    ("e_std_130", 0.08), ("e_lgt_80", 0.03), ("e_lgt_100", 0.04), ("e_lgt_120", 0.03),
    ("e_std_end_general", 0.04), ("e_std_np_start", 0.05), ("e_std_np_end", 0.04),
    ("e_roadWork", 0.03), ("e_curveLeft", 0.03), ("e_curveRight", 0.03),
    ("e_priorityRoad", 0.02), ("e_std_motorWay", 0.02), ("e_exitRight", 0.04),
)


_F32_MAX = 3.4028234663852886e38
_INT64 = INT_RANGE["int64"]
_WIRE = {**INT_RANGE, "bool": (0, 1)}  # a bool member holds 0 or 1
_REAL = ("real32", "real64")


@dataclass(frozen=True)
class LayoutLeaf:
    lo: float
    hi: float
    real: bool

    def clamp(self, value: float) -> float | int:
        if self.real:
            return float(min(max(value, self.lo), self.hi))
        return int(min(max(round(value), self.lo), self.hi))


@dataclass(eq=False)  # a node is itself (hashable by identity): range trees live for the process
class LayoutNode:
    members: dict[str, LayoutNode | LayoutLeaf]
    count: int | None = None  # element count when the member is an array of structs


def _leaf(member: Member) -> LayoutLeaf:
    if member.type in _REAL and member.bits is None:
        lo = -_F32_MAX if member.min is None else float(member.min)
        hi = _F32_MAX if member.max is None else float(member.max)
        return LayoutLeaf(lo, hi, True) if lo <= hi else LayoutLeaf(-_F32_MAX, _F32_MAX, True)
    if member.bits is not None:
        wlo, whi = 0, (1 << (member.bits[1] - member.bits[0] + 1)) - 1
    else:
        wlo, whi = _WIRE.get(member.type, (0, 0xFF))
    lo = wlo if member.min is None else max(wlo, math.ceil(member.min))
    hi = whi if member.max is None else min(whi, math.floor(member.max))
    return LayoutLeaf(lo, hi, False) if lo <= hi else LayoutLeaf(wlo, whi, False)


def _build(cat: Catalog, name: str, sw: SwKey) -> tuple[LayoutNode, Any]:
    """The range tree of struct ``name`` at ``sw`` and its shape (as :func:`_shape` gives it)."""
    sdef = cat.structs.get(name)
    var = sdef.variant_for(sw) if sdef else None
    if var is None:
        raise SpecError(f"struct {name} has no layout for {sw}")
    members: dict[str, LayoutNode | LayoutLeaf] = {}
    shape: list[tuple[str, Any]] = []
    for member in var.members:
        count = None if member.array is None else (
            member.array if isinstance(member.array, int) else cat.constant(member.array, sw))
        sub: Any = ""
        if member.bits is None and member.type not in _WIRE and member.type not in _REAL:
            child, sub = _build(cat, member.type, sw)
            members[member.name] = LayoutNode(child.members, count)
        else:
            members[member.name] = _leaf(member)
        shape.append((member.name, sub if count is None else ("L", count, sub if count else "")))
    return LayoutNode(members), tuple(shape)


def _shape(value: Any) -> Any:
    if isinstance(value, dict):
        return tuple((k, _shape(x)) for k, x in value.items())
    if isinstance(value, list):
        return ("L", len(value), _shape(value[0]) if value else "")
    return ""


def _merge(first: LayoutNode | LayoutLeaf, second: LayoutNode | LayoutLeaf
           ) -> LayoutNode | LayoutLeaf:
    """Ranges valid for both: intersection of leaves, union of members."""
    if isinstance(first, LayoutLeaf) and isinstance(second, LayoutLeaf):
        real = first.real and second.real
        lo, hi = max(first.lo, second.lo), min(first.hi, second.hi)
        if not real:
            lo, hi = math.ceil(lo), math.floor(hi)
        return LayoutLeaf(lo, hi, real) if lo <= hi else first
    if isinstance(first, LayoutNode) and isinstance(second, LayoutNode):
        members = dict(first.members)
        for key, member in second.members.items():
            members[key] = _merge(members[key], member) if key in members else member
        return LayoutNode(members, first.count if first.count is not None else second.count)
    return first


@cache
def _candidates(name: str) -> tuple[dict[Any, LayoutNode], LayoutNode] | None:
    """Range trees of DASP message ``name`` per distinct shape over all releases, and all merged."""
    cat = catalog()
    try:
        msg = cat.message(name)
    except SpecError:
        return None
    by_shape: dict[Any, LayoutNode] = {}
    for sw in cat.sw_versions:
        if msg.protocol != "DASP" or not msg.exists_in(sw):
            continue
        try:
            node, shape = _build(cat, msg.payload, sw)
        except SpecError:
            continue
        old = by_shape.get(shape)
        merged = node if old is None else _merge(old, node)
        assert isinstance(merged, LayoutNode)
        by_shape[shape] = merged
    if not by_shape:
        return None
    everything: LayoutNode | LayoutLeaf = LayoutNode({})
    for node in by_shape.values():
        everything = _merge(everything, node)
    assert isinstance(everything, LayoutNode)
    return by_shape, everything


def layout_node_for(name: str, values: dict[str, Any]) -> LayoutNode | None:
    cands = _candidates(name)
    if cands is None:
        return None
    by_shape, everything = cands
    if len(by_shape) == 1:
        return everything
    return by_shape.get(_shape(values), everything)


def child_struct(target: dict[str, Any], node: LayoutNode, key: str
                 ) -> tuple[dict[str, Any], LayoutNode] | None:
    sub, value = node.members.get(key), target.get(key)
    if isinstance(sub, LayoutNode) and isinstance(value, dict | StructView):
        return cast("dict[str, Any]", value), sub  # a packer's view serves as the dict
    return None


def struct_elements(target: dict[str, Any], node: LayoutNode, key: str
                    ) -> tuple[list[dict[str, Any]], LayoutNode]:
    sub, value = node.members.get(key), target.get(key)
    if isinstance(sub, LayoutNode) and isinstance(value, list):
        return [cast("dict[str, Any]", x) for x in value if isinstance(x, dict | StructView)], sub
    return [], LayoutNode({})


def member_at(target: Any, path: tuple[str | int, ...]) -> Any:
    """The member at ``path`` (struct member names, array indices) inside a value dict or a
    packer's view, or None where the layout has no such member."""
    for step in path:
        ok = (isinstance(target, dict | StructView) and step in target) or (
            isinstance(target, list) and isinstance(step, int) and step < len(target))
        target = target[step] if ok else None
    return target


@cache
def enum_code(enum: str, name: str, default: int) -> int:
    """Value of ``name`` in enum ``enum`` of specs/, ``default`` if the catalogue lacks it."""
    enum_def = catalog().enums.get(enum)
    if enum_def is not None:
        for entry in enum_def.values.values():
            if entry.name == name:
                return entry.value
    return default


# -- obstacle columns: (path inside eyeq_vision_object_t, member, real) --------------------------
_PS, _AS, _RECT = ("physicalState",), ("angularState",), ("imageBox", "rect")
_OBJ_F: tuple[tuple[tuple[str | int, ...], str], ...] = tuple(
    [(_PS, k) for k in (
        "width", "widthStd", "length", "lengthStd", "height", "heightStd",
        "absoluteLongVelocity", "absoluteLongVelocityStd", "absoluteLatVelocity",
        "absoluteLatVelocityStd", "absoluteLongAcc", "absoluteLongAccStd", "absoluteLatAcc",
        "absoluteLatAccStd", "longDistance", "longDistanceStd", "latDistance", "latDistanceStd",
        "heading")]
    + [(_AS, k) for k in (
        "angleRight", "angleRightStd", "angleLeft", "angleLeftStd", "angleSide", "angleSideStd",
        "angleMid", "angleMidStd", "angularSpeed", "angularSpeedStd")]
    + [((), "confidence"), ((), "ttc_const_vel")])
_EDGE_KEYS = ("xCoord", "yTopCoord", "yBottomCoord", "isOccluded", "valid")
_OBJ_I: tuple[tuple[tuple[str | int, ...], str], ...] = tuple(
    [(_RECT, k) for k in ("xLeftCoord", "xRightCoord", "yTopCoord", "yBottomCoord")]
    + [(("imageBox", "verticalEdges", e), k) for e in range(4) for k in _EDGE_KEYS]
    + [(("imageBox",), "visibleRect"), (("imageBox",), "visibleSide")]
    + [(("mobilityState",), k) for k in ("motionStatus", "motionCategory", "motionOrientation")]
    + [((), k) for k in ("age", "id", "classification", "isCipv", "laneAssignment")]
    + [(("lightIndicators",), k) for k in ("valid", "brake", "turnRight", "turnLeft")]
    + [((), k) for k in ("isPredicted", "isInDrivableArea", "isVeryClose")])
AGE_ROW = _OBJ_I.index(((), "age"))

Group = tuple[tuple[str | int, ...], list[tuple[str, bool, int]]]


@dataclass(eq=False)
class ObjectPlan:
    flo: FArr
    fhi: FArr
    ilo: IArr
    ihi: IArr
    groups: list[Group]


def _resolve(node: LayoutNode, path: tuple[str | int, ...], key: str) -> LayoutLeaf | None:
    for step in path:
        if isinstance(step, int):
            if node.count is None or step >= node.count:
                return None
            continue
        sub = node.members.get(step)
        if not isinstance(sub, LayoutNode):
            return None
        node = sub
    leaf = node.members.get(key)
    return leaf if isinstance(leaf, LayoutLeaf) else None


@cache
def obj_plan(elem: LayoutNode) -> ObjectPlan:
    flo, fhi = np.full(len(_OBJ_F), -np.inf), np.full(len(_OBJ_F), np.inf)
    ilo, ihi = np.full(len(_OBJ_I), _INT64[0]), np.full(len(_OBJ_I), _INT64[1])
    groups: dict[tuple[str | int, ...], list[tuple[str, bool, int]]] = {}
    for real, spec in ((True, _OBJ_F), (False, _OBJ_I)):
        for row, (path, key) in enumerate(spec):
            leaf = _resolve(elem, path, key)
            if leaf is None:
                continue
            if real:
                flo[row], fhi[row] = leaf.lo, leaf.hi
            else:
                ilo[row] = max(math.ceil(leaf.lo), _INT64[0])
                ihi[row] = min(math.floor(leaf.hi), _INT64[1])
            groups.setdefault(path, []).append((key, real, row))
    return ObjectPlan(flo, fhi, ilo.astype(np.int64), ihi.astype(np.int64), list(groups.items()))


# -- object motion: ordered rules over conditions that are bits of one index --------------------
# the conditions, one bit each (computed in Scene._columns)
(CROSSING, ONCOMING_VX, MOVING, VY_POS, VY_LEFT, VY_RIGHT, MOVING_IN, MOVING_OUT, PRECEDING,
 PASSING, FAST, VEHICLE_KIND) = (1 << k for k in range(12))
MOTION_BITS = 12


def _rules(enum: str, rules: list[tuple[int, str, int]], default: tuple[str, int]) -> IArr:
    """Codes of enum ``enum`` per index of :data:`MOTION_BITS` condition bits: the first rule
    (mask, name, fallback value) whose mask bits are all set picks its code, else ``default``
    (the ``np.select`` of the conditions, as a table)."""
    index = np.arange(1 << MOTION_BITS)
    out = np.full(1 << MOTION_BITS, enum_code(enum, *default), dtype=np.int64)
    for mask, name, fallback in reversed(rules):  # the first rule last: it wins where it holds
        out[index & mask == mask] = enum_code(enum, name, fallback)
    return out


@cache
def motion_tables() -> IArr:
    """motionStatus, motionCategory and motionOrientation (rows) per condition index."""
    status = _rules("object_motion_status", [
        (FAST, "moving", 1), (MOVING, "Moving_slowly", 4), (VEHICLE_KIND, "Stopped", 3)],
        ("stationary", 2))
    category = _rules("object_motion_category", [
        (CROSSING, "Crossing", 7), (ONCOMING_VX, "Oncoming", 12), (MOVING_IN, "Moving_in", 5),
        (MOVING_OUT, "Moving_out", 6), (MOVING | PRECEDING, "Preceding", 11),
        (MOVING | PASSING, "Passing", 1),
        (MOVING, "Moving", 10)], ("Undefined", 0))
    orientation = _rules("object_motion_orientation", [
        (CROSSING | VY_POS, "Crossing_left", 6), (CROSSING, "Crossing_right", 2),
        (ONCOMING_VX | VY_LEFT, "Oncoming_drifting_left", 5),
        (ONCOMING_VX | VY_RIGHT, "Oncoming_drifting_right", 3), (ONCOMING_VX, "Oncoming", 4),
        (MOVING | VY_LEFT, "Drifting_left", 7), (MOVING | VY_RIGHT, "Drifting_right", 1),
        (MOVING, "Preceding", 8)], ("Unknown", 0))
    return np.array((status, category, orientation))


BIT_WEIGHTS = np.array([1 << k for k in range(MOTION_BITS)], dtype=np.int64)



def frame_index(time_s: float) -> int:
    return max(0, math.floor(time_s * FRAME_RATE + 1e-6))


CLASS_P = np.array([c[1] for c in CLASSES]) / sum(c[1] for c in CLASSES)
XS = np.linspace(0.0, 100.0, 21)  # road-fit sample points ahead
DXS = np.diff(XS)
PINV = np.linalg.pinv(np.stack([XS**2, XS**3], axis=1))
SIGN_KEYS = (
    "signLongPosition", "signLatPosition", "signHeight", "signConfidence", "signSuppConfidence1",
    "signSuppConfidence2", "relevancyConfidence", "signPositionBottom", "signPositionLeft",
    "signPositionRight", "signPositionTop", "signType", "signSupplementalType1",
    "signSupplementalType2", "signID", "signRelevantDecision", "signFilterType")
SPOT_KEYS = (
    "leftAngle", "rightAngle", "topAngle", "bottomAngle", "id", "vdID", "longPos", "pixelTop",
    "pixelBottom", "pixelLeft", "pixelRight", "classification", "isTruck")
REFLECT_KEYS = (
    "lightSignLeftAngle", "lightSignRightAngle", "lightSignBottomAngle", "lightSignTopAngle",
    "lightSignID", "lightSignDistance", "lightSignGlareLevelMax", "lightSignGlareLevelCurrent")
FILLERS = {
    "EYEQ_VIS_OBSTACLES_MSG": "_fill_obstacles", "EYEQ_VIS_ROAD_DATA_MSG": "_fill_road",
    "EYEQ_VIS_TRAFFIC_SIGNS_MSG": "_fill_signs", "EYEQ_VIS_LIGHT_SENSOR_DATA_MSG": "_fill_lights",
    "EYEQ_VIS_AEB_INFO_MSG": "_fill_aeb", "EYEQ_VIS_FAILSAFE_MSG": "_fill_failsafe",
    "EYEQ_VIS_SRP_MSG": "_fill_srp", "EYEQ_TIMESYNC_MSG": "_fill_timesync",
    "EYEQ_SAFETY_MSG": "_fill_nothing", "EYEQ_DYNAMIC_CAL_MSG": "_fill_dynamic_cal",
}


@cache
def sign_table() -> tuple[tuple[str, ...], tuple[int, ...], FArr]:
    rows = [(n, enum_code("traffic_sign", n, -1), w) for n, w in SIGNS]
    rows = [r for r in rows if r[1] >= 0] or [("e_std_80", 7, 1.0)]
    weights = np.array([r[2] for r in rows])
    return tuple(r[0] for r in rows), tuple(r[1] for r in rows), weights / weights.sum()


def cumtrapz(y: FArr, dx: FArr) -> FArr:
    """The cumulative trapezoid integral of ``y`` over steps ``dx`` (``np.diff`` of x)."""
    return np.concatenate(([0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * dx)))


# -- what the scene's writer shares between frames ---------------------------------------------
@cache
def lane_codes() -> IArr:
    return np.array([enum_code("object_lane_assignment", n, v) for n, v in (
        ("RIGHT_NEXT_NEXT", 2), ("RIGHT_NEXT", 1), ("EGO_LANE", 0), ("LEFT_NEXT", -1),
        ("LEFT_NEXT_NEXT", -2))])


# (a, b) of the obstacles' standard deviations a + b·|longDistance| (physicalState, angularState)
STD = np.array([(0.05, 0.002), (0.2, 0.01), (0.1, 0.01), (0.1, 0.005), (0.2, 0.004),
                 (0.2, 0.002), (0.05, 0.003), (0.005, 1e-4)])
# light spots: a pair of lamps unless a two-wheeler; the truck flag
PAIR_LAMPS = tuple(c[0] not in ("bike", "bicycle") for c in CLASSES)
TRUCK = next(k for k, c in enumerate(CLASSES) if c[0] == "truck")
BORDER_OFFSET = {"leftRoadBorder": 3 * HALF_LANE + 0.8, "rightRoadBorder": -3 * HALF_LANE - 0.6}
PX = np.array([[-FOCAL_PX], [-FOCAL_PX], [FOCAL_PX]])  # the image rows' factors


@cache
def struct_members(node: LayoutNode) -> list[tuple[str, LayoutNode]]:
    """The members of ``node`` that are one struct (not an array of them): where
    :meth:`Scene.fill` writes a header too."""
    return [(k, sub) for k, sub in node.members.items()
            if isinstance(sub, LayoutNode) and sub.count is None]
