"""A seeded, reproducible driving scene that fills the simulated EyeQ's DASP payloads (§7.1.4).

:class:`Scene` adds to the world of :mod:`eyeq_spi.sim.scene_world` what the EyeQ reports of it.
:meth:`Scene.fill` only reads state, so the same seed and step times give the same payloads, and
knows nothing of the SW version: it recognises the layout from the shape of the value dict and
clamps each value into the member's declared range and wire type."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from eyeq_spi.sim.dasp_fast import StructView
from eyeq_spi.sim.scene_layout import (
    AGE_ROW,
    BIT_WEIGHTS,
    BORDER_OFFSET,
    CAM_HEIGHT,
    CLASS_DEFAULT,
    CLASSES,
    CYCLIST,
    FILLERS,
    FOCAL_PX,
    HALF_LANE,
    IMAGE_H,
    IMAGE_W,
    ONCOMING,
    PAIR_LAMPS,
    PX,
    REFLECT_KEYS,
    SIGN_KEYS,
    SPOT_KEYS,
    STD,
    TRUCK,
    TTC_NONE,
    VEHICLE,
    FArr,
    IArr,
    LayoutNode,
    child_struct,
    enum_code,
    frame_index,
    lane_codes,
    layout_node_for,
    member_at,
    motion_tables,
    obj_plan,
    struct_elements,
    struct_members,
)
from eyeq_spi.sim.scene_world import SceneConfig, SceneWorld
from eyeq_spi.sim.scene_write import (
    put_values,
    puts_once,
    write_objects_packed,
    write_table,
)

__all__ = ["CLASSES", "Scene", "SceneConfig", "SceneWorld"]


class Scene:
    """What the EyeQ reports of a :class:`SceneWorld`: the writer of its DASP payloads."""

    def __init__(self, config: SceneConfig | None = None) -> None:
        self.world = SceneWorld(config)
        self._cls_code = np.array(
            [enum_code("object_classification", c[0], CLASS_DEFAULT[c[0]]) for c in CLASSES])
        self._cols: tuple[FArr, IArr, IArr] | None = None
        # per message: the value dict or view last filled, its range tree and its filler's name
        self._nodes: dict[str, tuple[dict[str, Any], LayoutNode | None, str]] = {}

    def step(self, t: float, ego_speed: float | None = None, yaw_rate: float | None = None) -> None:
        """:meth:`SceneWorld.step`, then the vectorised part of filling the obstacles (once per
        step)."""
        if self.world.step(t, ego_speed, yaw_rate):
            self._cols = None
            self._columns()

    def _columns(self) -> tuple[FArr, IArr, IArr]:
        """Rows of :data:`_OBJ_F` / :data:`_OBJ_I` for the live objects in id order, and their
        birth frames; computed once per step."""
        world = self.world
        if self._cols is not None:
            return self._cols
        idx = world.alive.nonzero()[0]
        idx = idx[world.oid[idx].argsort(kind="stable")]
        # the state of the live objects as rows of two matrices: one gather for all columns.
        # Below, what several rows share is computed once and the same operation on several
        # rows is one numpy call on a matrix: elementwise, the same numbers as row by row
        s, d, vx, vy, ax, ay, w, length, hgt, dtgt, cbias = np.array((
            world.s, world.d, world.vx, world.vy, world.ax, world.ay, world.width, world.length,
            world.height, world.dtgt, world.cbias))[:, idx]
        kind, oid, cls, birth = np.array((world.kind, world.oid, world.cls, world.birth))[:, idx]
        c1, c2, c3 = world.poly[1:]
        y = world.lateral(s, d)
        vrel, a_s, ss = vx - world.v, np.abs(s), np.maximum(s, 0.5)
        speed = np.hypot(vx, vy)
        moving = speed >= 0.3
        road_heading = np.arctan(c1 + s * (2 * c2 + 3 * c3 * s))
        # §13.2.5.4: angles are measured from Z with "the positive side to the host's right";
        # y (latDistance) is left positive (ISO 8855), hence atan2(-y, ...)
        hw, ny = w / 2, -y
        right, left = hw - y, ny - hw  # w/2 - y, -y - w/2
        far = ss + length
        at = np.arctan2(np.array((vy, ny, right, left, right, left)),
                        np.array((vx, ss, far, far, ss, ss)))
        heading = np.where(moving, at[0], 0.0) + road_heading
        heading = (heading + math.pi) % (2 * math.pi) - math.pi
        mid = at[1]
        on_left, on_right = y > HALF_LANE, y < -HALF_LANE  # we see its right / left side
        side = np.where(on_left, at[2], np.where(on_right, at[3], mid))
        ang_std = 0.002 + 5e-5 * a_s
        closing = -vrel
        ttc = np.where((s > 0.0) & (closing > 0.1),
                       np.minimum(s / np.maximum(closing, 0.1), TTC_NONE), TTC_NONE)
        age = world.frame_now - birth + 1
        conf = np.clip(0.97 - 0.0015 * a_s + cbias
                    - 0.2 * np.exp(-np.maximum(age, 1) / 6.0), 0.5, 1.0)
        # the standard deviations a + b·|s| (STD) in two numpy steps for all of them: the same
        # multiplication and addition per element as one row at a time
        sd = STD[:, :1] + STD[:, 1:] * a_s
        floats = np.array([
            w, sd[0], length, sd[1], hgt, sd[0], vx, sd[2], vy, sd[3], ax, sd[4], ay, sd[5],
            s, 0.05 + 0.01 * a_s + 5e-5 * s * s, y, sd[6], heading,
            at[4], ang_std, at[5], ang_std, side, ang_std,
            mid, ang_std, -(ss * vy - y * vrel) / (ss * ss + y * y), sd[7],
            conf, ttc], dtype=np.float64)
        zero = np.zeros(len(idx))
        lane = world.lane_index(d)
        lanes = lane_codes()
        lane_code = np.where(np.abs(lane) > 2, enum_code("object_lane_assignment", "UNKNOWN", 3),
                             lanes[np.clip(lane, -2, 2) + 2])
        vehicle = kind <= ONCOMING
        cipv = np.where(vehicle | (kind == CYCLIST), enum_code("object_is_cipv", "no_CIPV", 1),
                        enum_code("object_is_cipv", "not_relevant", 0))
        ahead = (lane == 0) & (s > 0.0)
        if ahead.any():
            cipv[int(np.argmin(np.where(ahead, s, np.inf)))] = enum_code("object_is_cipv", "CIPV",
                                                                          2)
        err = dtgt - d
        signal = kind == VEHICLE
        ints = np.array([
            *self._image(s, y, hw, hgt, ss, far, vx, on_left, on_right),
            *self._motion(s, vx, vy, vrel, lane, kind, speed, moving, d, dtgt),
            zero, oid, self._cls_code[cls], cipv, lane_code,
            vehicle, signal & (ax < -1.0), signal & (err < -0.5), signal & (err > 0.5),
            zero, np.abs(d) < 3 * HALF_LANE + 0.5, (s < 3.0) & (np.abs(y) < 3.0)],
            dtype=np.float64)
        self._cols = (floats, np.rint(ints).astype(np.int64), birth)
        return self._cols

    @staticmethod
    def _image(s: FArr, y: FArr, hw: FArr, hgt: FArr, ss: FArr, far: FArr, vx: FArr,
               on_left: npt.NDArray[np.bool_], on_right: npt.NDArray[np.bool_]) -> list[FArr]:
        """The image rows: bounding rect, back/front and side rects with their visibility,
        which rect and which side is seen. Image origin at the centre, x right, y down (the
        rect is for visualisation); -FOCAL_PX * (y + w/2), -FOCAL_PX * (y - w/2),
        FOCAL_PX * (CAM_HEIGHT - hgt)."""
        vis = s > 0.5
        px = np.array((y + hw, y - hw, CAM_HEIGHT - hgt)) * PX
        u_l, u_r, v_t = px / ss
        v_b = FOCAL_PX * CAM_HEIGHT / ss
        side_vis = vis & (on_left | on_right)
        u_s, v_ts, v_bs = np.where(side_vis, np.array((
            np.where(on_left, px[1], px[0]), px[2], np.full(len(s), FOCAL_PX * CAM_HEIGHT)))
            / far, 0.0)
        zero = np.zeros(len(s))
        return [
            u_l, u_r, v_t, v_b,
            u_l, v_t, v_b, zero, vis, u_r, v_t, v_b, zero, vis,
            u_s, v_ts, v_bs, zero, side_vis, zero, zero, zero, zero, zero,
            np.where(vis, np.where(vx < -0.5, enum_code("object_visible_rect", "Front", 1),
                                   enum_code("object_visible_rect", "Back", 2)), 0),
            np.where(vis & on_left, enum_code("object_visible_side", "Right", 1),
                     np.where(vis & on_right, enum_code("object_visible_side", "Left", 2), 0))]

    @staticmethod
    def _motion(s: FArr, vx: FArr, vy: FArr, vrel: FArr, lane: IArr, kind: IArr, speed: FArr,
                moving: npt.NDArray[np.bool_], d: FArr, dtgt: FArr) -> IArr:
        """motionStatus, motionCategory and motionOrientation (rows): each object's conditions
        as the bits of one index into the rule tables of :func:`motion_tables`."""
        changing = kind == VEHICLE
        bits = BIT_WEIGHTS @ np.array((  # CROSSING .. VEHICLE_KIND
            np.abs(vy) > np.maximum(np.abs(vx), 0.5), vx < -1.0, moving, vy > 0, vy > 0.3,
            vy < -0.3, changing & (np.abs(dtgt) < np.abs(d) - 0.5),
            changing & (np.abs(dtgt) > np.abs(d) + 0.5), (lane == 0) & (s > 0.0) & (vx > 0.5),
            (lane != 0) & (vrel > 1.0) & changing, speed >= 2.0, kind <= ONCOMING),
            dtype=np.int64)
        out: IArr = motion_tables()[:, bits]
        return out

    # -- payloads ----------------------------------------------------------------------------
    def fill(self, name: str, values: dict[str, Any], now: float) -> None:
        """Write the scene into a ``zero_values()`` dict of DASP message ``name`` (any SW
        version), or into a :class:`~eyeq_spi.sim.dasp_fast.DaspPacker`'s root view (the same
        writes, packed in place); members the layout lacks are skipped, unknown messages are
        left unchanged."""
        last = self._nodes.get(name)
        if last is None or last[0] is not values:  # a new dict or view: find its layout
            method = FILLERS.get(name)
            if method is None:
                return
            # a packer's view has the shape of its template dict (the same ranges)
            shape = values.template if isinstance(values, StructView) else values
            last = self._nodes[name] = (
                values, None if shape is None else layout_node_for(name, shape), method)
        node = last[1]
        if node is None:
            return
        now = float(now)
        header = self._header_values(now)  # the same for every header of one instant
        put_values(values, node, header)
        for key, sub in struct_members(node):
            if isinstance(values.get(key), dict | StructView):
                put_values(values[key], sub, header)
        getattr(self, last[2])(values, node, now)

    def _header_values(self, now: float) -> dict[str, float]:
        """The values of every header of instant ``now``."""
        frame = frame_index(now)
        return {"timestamp_ms": int(now * 1000) & 0xFFFFFFFF,
                "timestamp_us": max(0, round(now * 1e6)), "frameIndex": frame & 0xFFFFFFFF,
                "imageIndex": frame & 0xFFFF, "vehIndexUsed": self.world.veh_index & 0xFFFFFFFF}

    def _fill_nothing(self, values: dict[str, Any], node: LayoutNode, now: float) -> None:
        """Headers only (EYEQ_SAFETY_MSG: no safety fault, no challenge)."""

    def _fill_obstacles(self, values: dict[str, Any], node: LayoutNode, now: float) -> None:
        vis = child_struct(values, node, "visObjects")
        if vis is None:
            return
        objs, elem = struct_elements(*vis, "visObs")
        if not objs:
            return
        plan = obj_plan(elem)
        floats, ints, birth = self._columns()
        count = min(floats.shape[1], len(objs))
        ints = ints[:, :count].copy()
        ints[AGE_ROW] = np.maximum(frame_index(now) - birth[:count] + 1, 1)
        fa = np.clip(floats[:, :count], plan.flo[:, None], plan.fhi[:, None])
        ia = np.clip(ints, plan.ilo[:, None], plan.ihi[:, None])
        if isinstance(objs[0], StructView) and write_objects_packed(objs, plan, fa, ia, count):
            return
        fl, il = fa.tolist(), ia.tolist()
        for index, obj in enumerate(objs):
            for path, items in plan.groups:
                target = member_at(obj, path)
                if not isinstance(target, dict | StructView):  # absent in this release
                    continue
                for key, real, row in items:
                    if key not in target:
                        continue
                    if index < count:
                        target[key] = (fl if real else il)[row][index]
                    else:  # no object: id 0 marks the slot invalid (§13.2.2)
                        target[key] = 0.0 if real else 0

    def _poly_values(self, offset: float, end: float) -> dict[str, float]:
        c0, c1, c2, c3 = self.world.poly
        return {"a0": c0 + offset, "a1": c1, "a2": c2, "a3": c3, "startRange": 5.0,
                "endRange": end}

    def _fill_marker(self, md: dict[str, Any], mn: LayoutNode,
                     spec: tuple[float, str, float, float] | None) -> None:
        poly, conf = child_struct(md, mn, "laneMarker"), child_struct(md, mn, "laneMarkerConf")
        lmt = "lane_marker_type"
        # each marker's spec is None or of one kind for good: its constants are written once
        if spec is None:  # §10.6: only seen with a wide separation between lanes
            if poly:
                puts_once(*poly, "none", lambda: dict.fromkeys(self._poly_values(0.0, 0.0), 0.0))
            if conf:
                puts_once(*conf, "none", lambda: {"sfConf": 0.0, "confidence": 0})
            puts_once(md, mn, "none", lambda: {
                "measuredViewRange": 0.0, "laneMarkerWidth": 0.0,
                "laneMarkerType": enum_code(lmt, "INVALID", 6), "dlmType": 0, "decelType": 0,
                "laneMarkerColor": 0})
            return
        offset, kind, view, phase = spec
        if poly:
            put_values(*poly, self._poly_values(offset, view))
        if conf:
            put_values(*conf, {"sfConf": 0.9 + 0.06 * math.sin(0.5 * self.world.tau + phase)})
            puts_once(*conf, "seen", lambda: {
                "confidence": enum_code("road_confidence_level", "Detected lanemark", 3)})
        put_values(md, mn, {"measuredViewRange": view * (0.85 if kind == "DASHED" else 0.95)})
        puts_once(md, mn, kind, lambda: {
            "laneMarkerWidth": 0.12 if kind == "DASHED" else 0.15,
            "laneMarkerType": enum_code(lmt, kind, 0),
            "dlmType": enum_code("dlm_type", "NOTDLM", 0),
            "decelType": enum_code("decel_type", "NOTDECEL", 0),
            "laneMarkerColor": enum_code("lane_marker_color", "White", 1)})

    def _fill_road(self, values: dict[str, Any], node: LayoutNode, now: float) -> None:
        world = self.world
        info = child_struct(values, node, "roadInfo")
        if info is None:
            return
        rd, rn = info
        phase = world.phase
        # min(max()) is np.clip on one float (NaN kept), without numpy's call overhead
        view = float(min(max(min(105.0 + 12.0 * math.sin(0.2 * world.tau + phase[2]),
                                 world.cipv_distance() + 25.0), 20.0), 128.0))
        markers: dict[str, tuple[float, str, float, float] | None] = {
            "hostLeftMarker": (HALF_LANE, "DASHED", view, phase[3]),
            "hostRightMarker": (-HALF_LANE, "DASHED", view, phase[4]),
            "nextLeftLeftMarker": (3 * HALF_LANE, "SOLID", 0.75 * view, phase[5]),
            "nextRightRightMarker": (-3 * HALF_LANE, "SOLID", 0.75 * view, phase[6]),
            "nextLeftRightMarker": None, "nextRightLeftMarker": None}
        mi = child_struct(rd, rn, "roadMarkerInfo")
        if mi:
            for key, spec in markers.items():
                marker = child_struct(*mi, key)
                if marker:
                    self._fill_marker(*marker, spec)
            puts_once(*mi, "road", lambda: {
                "ambiguousLinePatternLeft": 0, "ambiguousLinePatternRight": 0,
                "constructionArea": 0, "roadPredictionLeft": 0, "roadPredictionRight": 0})
        bi = child_struct(rd, rn, "roadBorderInfo")
        borders = (("leftRoadBorder", BORDER_OFFSET["leftRoadBorder"], "Barrier", 4, 0.8),
                   ("rightRoadBorder", BORDER_OFFSET["rightRoadBorder"], "Curb", 3, 0.15))
        for key, offset, kind, default, height in borders if bi else ():
            border = child_struct(*bi, key) if bi else None
            if border is None:
                continue
            poly = child_struct(*border, "roadBorder")
            conf = child_struct(*border, "roadBorderConf")
            if poly:
                put_values(*poly, self._poly_values(offset, 0.6 * view))
            if conf:
                puts_once(*conf, "border", lambda: {"sfConf": 0.8, "confidence": enum_code(
                    "road_confidence_level", "Detected lanemark", 3)})
            puts_once(*border, "border", lambda h=height, k=kind, v=default: {  # type: ignore[misc]
                "roadBorderHeight": h, "roadBorderType": enum_code("road_border_type", k, v)})
        hpp = child_struct(rd, rn, "roadHppFusionInfo")
        if hpp:
            centre = child_struct(*hpp, "laneCenter")
            if centre:
                put_values(*centre, self._poly_values(0.0, view))
            puts_once(*hpp, "hpp", lambda: {
                "roadFusionConf": 0.92, "halfWidth": HALF_LANE, "hppLeftWeight": 0.5,
                "hppCenterWeight": 0.0, "hppRightWeight": 0.5, "roadLeftWeight": 0.5,
                "roadRightWeight": 0.5})
        puts_once(rd, rn, "road", lambda: {
            "drivingSide": enum_code("road_driving_side", "Right Side", 0),
            "laneChange": enum_code("road_lane_change", "No lane change", 0)})

    def _visible_signs(self) -> tuple[IArr, FArr]:
        """Signs ahead, nearest first, and their lateral distances."""
        world = self.world
        idx = (world.sg_alive & (world.sg_s > 0.0)).nonzero()[0]
        idx = idx[world.sg_s[idx].argsort(kind="stable")]
        return idx, world.lateral(world.sg_s[idx], world.sg_lat[idx])

    def _fill_signs(self, values: dict[str, Any], node: LayoutNode, now: float) -> None:
        world = self.world
        tsr = child_struct(values, node, "tsrInfo")
        if tsr is None:
            return
        elems, en = struct_elements(*tsr, "trafficSigns")
        idx, y_all = self._visible_signs()
        count = min(len(elems), len(idx))
        rows: list[tuple[float, ...]] = []
        s_l, z_l, bias, lat, typ, sid = (a[idx[:count]].tolist() for a in (
            world.sg_s, world.sg_z, world.sg_bias, world.sg_lat, world.sg_type, world.sg_id))
        decision = enum_code("tsr_sign_relevant_decision", "RELEVANT_SIGN", 0)
        filt = enum_code("tsr_sign_filter_type", "NO_SLI_FILTER", 0)
        for index, y in enumerate(y_all[:count].tolist()):
            s, z = s_l[index], z_l[index]
            ss = max(s, 1.0)
            u, v = IMAGE_W / 2 - FOCAL_PX * y / ss, IMAGE_H / 2 - FOCAL_PX * (z - CAM_HEIGHT) / ss
            half = FOCAL_PX * 0.35 / ss
            # SIGN_KEYS; §16: "a positive value indicates the sign is on the right", and
            # signHeight is the "height of sign relative to the sensor"
            rows.append((
                s, -y, z - CAM_HEIGHT,
                min(1.0, 0.6 + 0.4 * (1.0 - s / 100.0) + bias[index]), 0.0, 0.0,
                0.95 if lat[index] < 0.0 else 0.85, v + half, u - half, u + half, v - half,
                typ[index], 0, 0, sid[index], decision, filt))
        write_table(elems, en, SIGN_KEYS, rows)
        put_values(*tsr, {"numberTrafficSigns": len(rows)})
        puts_once(*tsr, "tsr",
                  lambda: {"currentMarket": enum_code("tsr_current_market", "EUROPE", 1)})
        marks = child_struct(*tsr, "roadMarkings")
        if marks:
            puts_once(*marks, "none", lambda: dict.fromkeys((
                "numberOfArrowsMarkings", "numberOfStopLinesMarkings",
                "numberOfSpeedLimitMarkings", "numberOfCrossingMarkings"), 0))

    def _spot_rows(self, count: int) -> tuple[list[tuple[float, ...]], bool]:
        """The light spots' rows (tuples in the order of :data:`SPOT_KEYS`), nearest first,
        and whether an oncoming vehicle is among them."""
        world = self.world
        lit = (world.alive & (world.kind <= CYCLIST) & (world.s > 3.0)).nonzero()[0]
        lit = lit[world.s[lit].argsort(kind="stable")][:min(world.n_spots, count)]
        vsign = -1.0 if world.config.spot_angles_up else 1.0  # top, bottom: below-positive
        # the arrays as Python numbers first (the same values float() of an element gives)
        rows: list[tuple[float, ...]] = []
        s_l, w_l, cls_l, kind_l, oid_l = (a[lit].tolist() for a in (
            world.s, world.width, world.cls, world.kind, world.oid))
        y_l = world.lateral(world.s[lit], world.d[lit]).tolist()
        atan2, tan = math.atan2, math.tan
        spot_enum = "light_spot_classification"
        codes = (enum_code(spot_enum, "Pair of Headlamps", 3),
                 enum_code(spot_enum, "Pair of Tail-lamps", 4),
                 enum_code(spot_enum, "Tail-lamp", 2))
        for s, y, w, ci, kind, oid in zip(s_l, y_l, w_l, cls_l, kind_l, oid_l, strict=True):
            half = max(w / 2 - 0.15, 0.0)
            # §15 light spots: "angles to the right of the sensor coordinate system are
            # positive"; "angle above the horizon are positive" from SW4.0 (line 3295), below
            # before it (line 3257); pixels from the image's left bottom corner
            left, right = atan2(-y - half, s), atan2(half - y, s)
            top, bottom = atan2(CAM_HEIGHT - 1.0, s), atan2(CAM_HEIGHT - 0.6, s)
            rows.append((  # SPOT_KEYS
                left, right, vsign * top, vsign * bottom, oid, oid, s,
                IMAGE_H / 2 - FOCAL_PX * tan(top), IMAGE_H / 2 - FOCAL_PX * tan(bottom),
                IMAGE_W / 2 + FOCAL_PX * tan(left), IMAGE_W / 2 + FOCAL_PX * tan(right),
                codes[0] if kind == ONCOMING else codes[1] if PAIR_LAMPS[ci] else codes[2],
                float(ci == TRUCK)))
        return rows, ONCOMING in kind_l

    def _reflect_rows(self, count: int) -> list[tuple[float, ...]]:
        """The reflective signs' rows (tuples in the order of :data:`REFLECT_KEYS`)."""
        world = self.world
        idx, y_all = self._visible_signs()
        idx = idx[:count]
        out: list[tuple[float, ...]] = []
        atan2 = math.atan2
        for s, z, sid, y in zip(world.sg_s[idx].tolist(), world.sg_z[idx].tolist(),
                                world.sg_id[idx].tolist(), y_all[:count].tolist(), strict=True):
            z -= CAM_HEIGHT
            glare = 100.0 * math.exp(-s / 50.0)
            out.append((  # §15: "Negative: left"
                atan2(-y - 0.4, s), atan2(0.4 - y, s), atan2(z - 0.4, s), atan2(z + 0.4, s),
                float(sid), s, min(100.0, glare + 10.0), glare))
        return out

    def _fill_lights(self, values: dict[str, Any], node: LayoutNode, now: float) -> None:
        info = child_struct(values, node, "activeLightSensorInfo")
        if info is None:
            return
        ld, ln = info
        spots, sn = struct_elements(ld, ln, "activeLightSpots")
        rows, oncoming_seen = self._spot_rows(len(spots))
        write_table(spots, sn, SPOT_KEYS, rows)
        signs, gn = struct_elements(ld, ln, "reflectiveSigns")
        refl = self._reflect_rows(len(signs))
        write_table(signs, gn, REFLECT_KEYS, refl)
        lit = len(rows) > 0
        put_values(ld, ln, {
            "numOfActiveLightSpots": len(rows), "numOfReflectiveSigns": len(refl),
            "clearFieldOfView": enum_code("ahbc_clear_field_of_view", "No Clear Field-Of-View", 1)
            if lit else enum_code("ahbc_clear_field_of_view", "Clear Field-Of-View", 2),
            "beamRequest": enum_code("ahbc_beam_request", "OFF" if lit else "ON", 0 if lit else 1),
            "oncomingLaneNotDark": int(oncoming_seen)})
        puts_once(ld, ln, "ahbc", lambda: {
            "ahbcAvailable": enum_code("ahbc_available", "Full", 2),
            "gridFrequency": enum_code("ahbc_grid_frequency", "50 Hz", 1),
            "inTunnel": enum_code("ahbc_in_tunnel", "FALSE", 1), "eventsDetected": 0,
            "fogDetected": 0, "highwayDetected": 1, "villageDetected": 0,
            "approachingJunction": 0, "lightNoisyScene": 0, "lightCone": 0})

    def _fill_aeb(self, values: dict[str, Any], node: LayoutNode, now: float) -> None:
        aeb = child_struct(values, node, "visAEB")
        if aeb:  # vision-only AEB stays quiet: the ego never closes in dangerously
            puts_once(*aeb, "quiet", lambda: {
                **{k: 0 for k in aeb[1].members if k.startswith("visOnly")},
                "roadFreeDetection": enum_code("aeb_road_free_detection", "NO_PENETRATION_DETECTED",
                                           0)})

    def _fill_failsafe(self, values: dict[str, Any], node: LayoutNode, now: float) -> None:
        fs = child_struct(values, node, "visFailsafes")
        if fs:
            none = enum_code("failsafe_severity", "NONE", 1)
            puts_once(*fs, "none", lambda: {
                **{k: none for k in fs[1].members if k.endswith("SeverityLevel")},
                "freeSight": enum_code("free_sight", "TRUE", 1), "outOfCalibTSR": 0})

    def _fill_srp(self, values: dict[str, Any], node: LayoutNode, now: float) -> None:
        world = self.world
        srp = child_struct(values, node, "visSRP")
        if srp is None:
            return
        two_pi, sin, s_e = 2 * math.pi, math.sin, world.s_e
        for key, phase in (("leftWheelDataPoints", float(world.phase[0])),
                           ("rightWheelDataPoints", float(world.phase[1]))):
            elems, en = struct_elements(*srp, key)
            # road profile under each wheel, 5..32 m ahead
            pos = [s_e + 5.0 + 3.0 * k for k in range(len(elems))]
            write_table(elems, en, ("height", "conf"), [
                (0.8 * sin(two_pi * p / 37.0 + phase) + 0.4 * sin(two_pi * p / 11.3 + 2 * phase),
                 15 - k) for k, p in enumerate(pos)])
        put_values(*srp, {"vehicleVelocity": world.v, "frameValid": 1})

    def _fill_timesync(self, values: dict[str, Any], node: LayoutNode, now: float) -> None:
        ts = child_struct(values, node, "timeSyncData")
        if ts:
            put_values(*ts, {"Frame_MCU_TS_Start": max(0, round((now - 0.03) * 1e6)),
                        "Last_MCU_Sync_TS": math.floor(now) * 1_000_000,
                        "Last_Clock_Sync_Skew": 0})

    def _fill_dynamic_cal(self, values: dict[str, Any], node: LayoutNode, now: float) -> None:
        world = self.world
        cal = child_struct(values, node, "dynamicCalParams")
        if cal is None:
            return
        progress = min(100.0, 10.0 * world.tau)
        yaw = 0.25 + 0.02 * math.sin(0.05 * world.tau)
        pitch = -0.4 + 0.02 * math.sin(0.07 * world.tau + 1.0)
        put_values(*cal, {
            "phYaw": yaw, "phPitch": pitch, "roll": 0.1, "camHeight": CAM_HEIGHT,
            "reserved": CAM_HEIGHT, "distYaw": FOCAL_PX * math.tan(math.radians(yaw)),
            "distPitch": FOCAL_PX * math.tan(math.radians(pitch)),
            "runMode": enum_code("dynamic_cal_run_mode", "AUTOFIX", 4),
            "status": enum_code("dynamic_cal_status", "SUCCESS" if progress >= 100 else "INIT",
                            1 if progress >= 100 else 0),
            "error": enum_code("dynamic_cal_error", "OK", 3), "overallProgress": progress})
