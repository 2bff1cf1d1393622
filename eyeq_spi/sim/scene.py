"""A seeded, reproducible driving scene that fills the simulated EyeQ's DASP payloads (§7.1.4).

Theory of operation
-------------------
The world lives in *road coordinates* relative to the ego vehicle: ``s`` is the distance along
the road ahead of the ego's front bumper, ``d`` the lateral offset from the centre of the ego
lane (left positive), lanes are 3.6 m wide. Every tracked object follows the seed's process model
(seed 002 §7.1): within one step its accelerations are constant, so
``s(t+dt) = s + (vx - v_ego)*dt + 0.5*ax*dt^2``. Between steps a small controller (IDM car
following, lane changes, a lateral PD) picks the accelerations for the next step, objects leave
when far behind or ahead and new ones spawn at once, so the number of objects stays as configured.

The road is a clothoid (seed 002 §7.2): curvature is piecewise linear in arc length, drifting
between straights and gentle curves. Each step fits ``c2 x^2 + c3 x^3`` to the road centre over
the next 100 m; ``c0``/``c1`` come from the ego's wander inside its lane. Lane markers, borders,
objects and signs all use that one polynomial, so they agree with each other.

All randomness is drawn in :meth:`Scene.step` from one ``np.random.Generator``; :meth:`Scene.fill`
only reads state, so the same seed and the same step times give the same payloads. ``fill`` knows
nothing of the SW version: it recognises the layout from the shape of the value dict and clamps
each value into the member's declared range and wire type (the intersection over every release
with that shape).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from eyeq_spi.sim.scene_layout import (
    _AGE_ROW,
    _CLASS_DEFAULT,
    _CLASS_P,
    _FILLERS,
    _PINV,
    _REFLECT_KEYS,
    _SIGN_KEYS,
    _SPOT_KEYS,
    _XS,
    CAM_HEIGHT,
    CLASSES,
    CYCLIST,
    EGO_LENGTH,
    EGO_SPEED_MAX,
    EGO_SPEED_MIN,
    FOCAL_PX,
    HALF_LANE,
    IMAGE_H,
    IMAGE_W,
    LANE_WIDTH,
    MAX_GAP,
    MAX_OBJECTS,
    MAX_SIGNS,
    MAX_SPOTS,
    MAX_SUBSTEP,
    ONCOMING,
    PEDESTRIAN,
    TTC_NONE,
    VEHICLE,
    FArr,
    IArr,
    _child,
    _choose,
    _code,
    _cumtrapz,
    _elements,
    _frame,
    _Node,
    _node_for,
    _obj_plan,
    _ObjPlan,
    _puts,
    _sign_table,
    _write_rows,
)


@dataclass
class SceneConfig:
    seed: int = 1
    objects: int = 8  # 0..15 tracked objects (E_EYEQ_MAX_VISION_OBJECTS = 15)
    signs: int = 4  # 0..20 traffic signs visible at a time
    light_spots: int = 4  # 0..15
    ego_speed: float = 25.0  # m/s, default constant-speed drive


# -- member ranges, recognised from the shape of a value dict ------------------------------------
class Scene:
    """The world (objects, road, signs) and the writer of its DASP payloads."""

    def __init__(self, config: SceneConfig | None = None) -> None:
        self.config = cfg = config or SceneConfig()
        self._rng = rng = np.random.default_rng(cfg.seed)
        self._n_obj = int(min(max(cfg.objects, 0), MAX_OBJECTS))
        self._n_signs = int(min(max(cfg.signs, 0), MAX_SIGNS))
        self._n_spots = int(min(max(cfg.light_spots, 0), MAX_SPOTS))
        self._t: float | None = None
        self._tau = 0.0  # s since the first step
        self._v = float(cfg.ego_speed)
        self._v_host: float | None = None
        self._k_host: float | None = None
        self._s_e = 0.0  # distance the ego has driven
        self._e = 0.0  # ego offset from its lane centre, left positive
        self._veh_index = 0
        self._frame_now = 0
        self._phase = rng.uniform(0.0, 2 * math.pi, 8)
        self._poly = (0.0, 0.0, 0.0, 0.0)
        self._knot_s, self._knot_k = [-200.0, 0.0], [0.0, 0.0]
        self._extend_road()
        n = MAX_OBJECTS
        self._alive = np.zeros(n, dtype=bool)
        self._oid, self._cls, self._kind, self._birth = (np.zeros(n, np.int64) for _ in range(4))
        self._s, self._d, self._vx, self._vy, self._ax, self._ay = (np.zeros(n) for _ in range(6))
        self._w, self._l, self._h, self._vdes, self._dtgt, self._cbias = (
            np.zeros(n) for _ in range(6))
        self._free_ids: deque[int] = deque(range(1, MAX_OBJECTS + 1))
        self._cls_code = np.array(
            [_code("object_classification", c[0], _CLASS_DEFAULT[c[0]]) for c in CLASSES])
        m = MAX_SIGNS
        self._sg_alive = np.zeros(m, dtype=bool)
        self._sg_id, self._sg_type = np.zeros(m, np.int64), np.zeros(m, np.int64)
        self._sg_s, self._sg_lat, self._sg_z, self._sg_bias = (np.zeros(m) for _ in range(4))
        self._free_sign_ids: deque[int] = deque(range(MAX_SIGNS))
        self._next_sign = float(rng.exponential(60.0)) + 20.0
        for k in range(self._n_obj):
            self._spawn(initial=True, first=k == 0)
        self._update_road(None, 0.0)
        self._cols: tuple[FArr, IArr, IArr] | None = None
        self._plans: dict[int, _ObjPlan] = {}
        self._nodes: dict[str, tuple[dict[str, Any], _Node | None]] = {}

    def unanchor(self) -> None:
        """Forget the time of the last step (after a warm-up): the next step anchors the scene
        in time as the first one does."""
        self._t = None

    # -- time --------------------------------------------------------------------------------
    def step(self, t: float, ego_speed: float | None = None, yaw_rate: float | None = None) -> None:
        """Advance the world to virtual time ``t`` (s, monotonic); ego state from the host's
        HOST_VEH_STATE_MSG when known, else the last known speed (or ``config.ego_speed``)."""
        t = float(t)
        if not math.isfinite(t):
            return
        if ego_speed is not None and math.isfinite(ego_speed):
            self._veh_index += 1
            # §7.1.2.2 vehicleVelocity range: no input may make a step unbounded
            self._v_host = min(max(float(ego_speed), EGO_SPEED_MIN), EGO_SPEED_MAX)
        v_target = self._v_host if self._v_host is not None else float(self.config.ego_speed)
        yaw = None if yaw_rate is None or not math.isfinite(yaw_rate) else float(yaw_rate)
        if self._t is None:  # the first step anchors the scene in time
            self._t, self._frame_now, self._v = t, _frame(t), v_target
            self._birth[self._alive] += self._frame_now
            self._update_road(yaw, 0.0)
            self._cols = None
            self._columns()
            return
        dt = t - self._t
        if dt <= 0.0:
            return
        skip = max(0.0, dt - MAX_GAP)
        n = max(1, math.ceil((dt - skip) / MAX_SUBSTEP - 1e-9))
        h, v0 = (dt - skip) / n, self._v
        self._tau += skip
        for i in range(n):
            va = v0 + (v_target - v0) * i / n
            vb = v0 + (v_target - v0) * (i + 1) / n
            self._integrate(h, va, vb)
            self._tau += h
            self._v = vb
            self._frame_now = _frame(self._t + skip + (i + 1) * h)
            self._update_road(yaw, h)
            self._decide(h)
        self._t = t
        self._cols = None
        self._columns()  # the vectorised part of filling EYEQ_VIS_OBSTACLES_MSG

    def _integrate(self, h: float, va: float, vb: float) -> None:
        """§7.1 constant-acceleration process model over ``h`` seconds, relative to the ego."""
        disp = 0.5 * (va + vb) * h
        self._s += self._vx * h + 0.5 * self._ax * h * h - disp
        self._vx += self._ax * h
        self._d += self._vy * h + 0.5 * self._ay * h * h
        self._vy += self._ay * h
        self._sg_s -= disp
        self._s_e += disp

    def _decide(self, h: float) -> None:
        self._despawn()
        while int(self._alive.sum()) < self._n_obj and self._spawn():
            pass
        self._lane_changes(h)
        self._accelerations(h)
        self._signs()

    # -- road --------------------------------------------------------------------------------
    def _extend_road(self) -> None:
        """§7.2 clothoids: curvature linear in arc length between straights and gentle arcs."""
        rng = self._rng
        if self._knot_s[-1] < self._s_e - 1000.0:
            # far behind (a jump in time or distance): restart the road at the ego instead of
            # generating every kilometre in between; keeps each step bounded
            self._knot_s = [self._s_e - 300.0, self._s_e - 100.0]
            self._knot_k = [self._knot_k[-1], self._knot_k[-1]]
        while self._knot_s[-1] < self._s_e + 400.0:
            straight = rng.random() < 0.4
            target = 0.0 if straight else float(np.clip(rng.normal(0.0, 0.001), -0.003, 0.003))
            s0, l1, l2 = self._knot_s[-1], rng.uniform(80.0, 200.0), rng.uniform(100.0, 400.0)
            self._knot_s += [s0 + l1, s0 + l1 + l2]
            self._knot_k += [target, target]
        while len(self._knot_s) > 3 and self._knot_s[1] < self._s_e - 200.0:
            del self._knot_s[0], self._knot_k[0]

    def _update_road(self, yaw_rate: float | None, h: float) -> None:
        self._extend_road()
        k = np.interp(self._s_e + _XS, self._knot_s, self._knot_k)
        if yaw_rate is not None and abs(self._v) > 1.0:
            # the host's yaw rate says how the road bends where the ego is
            target = float(np.clip(yaw_rate / self._v, -0.008, 0.008))
            kh = self._k_host
            kh = target if kh is None else kh + (target - kh) * min(1.0, h / 0.5)
            self._k_host = kh
            k = k - k[0] + kh
        else:
            self._k_host = None
        y = _cumtrapz(_cumtrapz(k, _XS), _XS)
        c2, c3 = (float(c) for c in _PINV @ y)
        p, tau = self._phase, self._tau
        w1, w2 = 2 * math.pi / 14.0, 2 * math.pi / 4.3
        self._e = 0.15 * math.sin(w1 * tau + p[0]) + 0.05 * math.sin(w2 * tau + p[1])
        e_dot = 0.15 * w1 * math.cos(w1 * tau + p[0]) + 0.05 * w2 * math.cos(w2 * tau + p[1])
        c1 = float(np.clip(-e_dot / max(abs(self._v), 1.0), -0.05, 0.05))
        self._poly = (-self._e, c1, float(np.clip(c2, -0.0099, 0.0099)),
                      float(np.clip(c3, -1.69e-4, 1.69e-4)))

    def _lateral(self, s: FArr, d: FArr) -> FArr:
        """Road (s, d) -> lateral distance in the ego frame through the road polynomial."""
        c0, c1, c2, c3 = self._poly
        out: FArr = d + c0 + s * (c1 + s * (c2 + s * c3))
        return out

    # -- objects -----------------------------------------------------------------------------
    def _clear(self, s: float, d: float, length: float) -> bool:
        if abs(d - self._e) < 2.5 and -EGO_LENGTH - 15.0 < s < 15.0:
            return False
        there = (np.abs(self._d - d) < 2.5) | (np.abs(self._dtgt - d) < 2.5)
        near = self._alive & there & (np.abs(self._s - s) < 15.0 + np.maximum(length, self._l))
        return not bool(near.any())

    def _place(self, name: str, kind: int, initial: bool, first: bool
               ) -> tuple[float, float, float]:
        """One candidate (s, d, target speed) for a new object of class ``name``."""
        rng, v_e = self._rng, max(self._v, 0.0)
        if kind == VEHICLE:
            vdes = float(np.clip(v_e * rng.uniform(0.8, 1.15) + rng.normal(0.0, 1.0), 0.0, 45.0))
            vdes = min(vdes, 25.0) if name == "truck" else vdes
            lane = int(rng.choice((-1, 0, 1)))
            if first:
                lane, s, vdes = 0, rng.uniform(25.0, 50.0), v_e * rng.uniform(0.97, 1.03)
            elif initial:
                s = rng.uniform(10.0, 150.0)
            elif vdes < v_e - 0.5 or v_e < 1.0:
                s = rng.uniform(100.0, 190.0)
                if lane == 0:  # the ego lane carries traffic at about the ego's speed
                    vdes = max(vdes, v_e * rng.uniform(0.97, 1.08))
            else:  # faster than the ego: comes from behind in a neighbour lane
                s = rng.uniform(-26.0, -14.0)
                lane = lane or int(rng.choice((-1, 1)))
            return s, lane * LANE_WIDTH, vdes
        if kind == ONCOMING:  # the other carriageway, beyond the left barrier
            vdes = float(np.clip(max(v_e, 15.0) * rng.uniform(0.8, 1.1), 5.0, 40.0))
            s = rng.uniform(30.0, 180.0) if initial else rng.uniform(150.0, 195.0)
            return s, float(rng.choice((8.2, 11.8))), -vdes
        if kind == CYCLIST:  # the right shoulder
            vdes = rng.uniform(3.5, 7.0)
            s = (rng.uniform(10.0, 90.0) if initial else
                 rng.uniform(70.0, 110.0) if vdes < v_e else rng.uniform(-12.0, -8.0))
            return s, -6.4 + rng.normal(0.0, 0.15), vdes
        # pedestrians on the sidewalks, walking either way
        d = (1.0 if rng.random() < 0.4 else -1.0) * rng.uniform(6.8, 8.0)
        vdes = rng.uniform(0.8, 1.6) * float(rng.choice((-1.0, 1.0)))
        s = rng.uniform(8.0, 70.0) if initial or v_e < 0.5 else rng.uniform(50.0, 85.0)
        return s, d, vdes

    def _spawn(self, initial: bool = False, first: bool = False) -> bool:
        free = np.flatnonzero(~self._alive)
        if len(free) == 0 or not self._free_ids:
            return False
        i, rng = int(free[0]), self._rng
        ci = 0 if first else int(rng.choice(len(CLASSES), p=_CLASS_P))
        kind = CLASSES[ci][5]
        if kind == VEHICLE and ci <= 1 and not first and rng.random() < 0.12:
            kind = ONCOMING
        for attempt in range(13):
            if attempt == 12:  # the road is full: someone on the sidewalk instead
                ci = next(k for k, c in enumerate(CLASSES) if c[5] == PEDESTRIAN)
                kind = PEDESTRIAN
            s, d, vdes = self._place(CLASSES[ci][0], kind, initial, first)
            if self._clear(s, d, CLASSES[ci][3]):
                break
        name, _, w, length, hgt, _ = CLASSES[ci]
        self._alive[i] = True
        self._oid[i] = self._free_ids.popleft()
        self._cls[i], self._kind[i] = ci, kind
        self._s[i], self._d[i], self._dtgt[i] = s, d, d
        self._vx[i], self._vdes[i] = vdes, vdes
        self._vy[i] = self._ax[i] = self._ay[i] = 0.0
        self._w[i] = float(np.clip(w * rng.normal(1.0, 0.04), 0.45, 2.9))
        self._l[i] = float(np.clip(length * rng.normal(1.0, 0.2 if name == "truck" else 0.06),
                                   0.45, 18.5))
        self._h[i] = float(np.clip(hgt * rng.normal(1.0, 0.04), 0.5, 4.0))
        self._cbias[i] = rng.normal(0.0, 0.015)
        self._birth[i] = self._frame_now - (int(rng.integers(0, 300)) if initial else 0)
        return True

    def _despawn(self) -> None:
        s, kind = self._s, self._kind
        behind = np.where(kind == VEHICLE, -30.0, np.where(kind == ONCOMING, -20.0, np.where(
            kind == CYCLIST, -15.0, -10.0)))
        far = (s < behind) | (s > np.where(kind <= ONCOMING, 200.0, np.where(
            kind == CYCLIST, 130.0, 95.0)))
        # an object the ego drives into is lost rather than driven through
        hit = (np.abs(self._d - self._e) < 1.6) & (s > -EGO_LENGTH - 1.0) & (s < 1.0)
        for i in np.flatnonzero(self._alive & (far | (hit & (kind != ONCOMING)))):
            self._alive[i] = False
            self._free_ids.append(int(self._oid[i]))
            self._oid[i] = 0

    def _change_lane(self, i: int, lane: int, escape: bool = False) -> bool:
        s, target = float(self._s[i]), lane * LANE_WIDTH
        if not -1 <= lane <= 1 or (lane == 0 and not escape and -40.0 < s < 30.0):
            return False
        others = self._alive.copy()
        others[i] = False
        there = (np.abs(self._d - target) < 2.5) | (np.abs(self._dtgt - target) < 0.5)
        gap = (6.0 if escape else 15.0) + np.maximum(self._l[i], self._l)
        busy = others & there & (np.abs(self._s - s) < gap)
        if busy.any():
            return False
        self._dtgt[i] = target
        return True

    def _lane_changes(self, h: float) -> None:
        rng, v_e, s = self._rng, self._v, self._s
        steady = self._alive & (self._kind == VEHICLE) & (np.abs(self._dtgt - self._d) <= 0.3)
        lane = self._lane_index(self._dtgt)
        closing = v_e - self._vx
        # the ego closes in on it: it gets out of the way or speeds up
        escape = steady & (lane == 0) & (s > -1.0) & (closing > 0.5) & (
            (s < 10.0 * closing) | (s < 0.8 * v_e + 5.0))
        u = rng.random((3, MAX_OBJECTS))
        for i in (int(k) for k in np.flatnonzero(escape)):
            if not (self._change_lane(i, -1, True) or self._change_lane(i, 1, True)):
                # boxed in: the whole ego lane ahead speeds up
                platoon = self._alive & (self._kind == VEHICLE) & (s > -1.0) & (
                    (lane == 0) | (self._lane_index(self._d) == 0))
                self._vdes[platoon] = np.maximum(self._vdes[platoon], v_e + 3.0)
        for i in (int(k) for k in np.flatnonzero(steady & ~escape & (u[0] < 0.03 * h))):
            self._change_lane(i, int(lane[i]) + (1 if u[1, i] < 0.5 else -1))
        drift = u[2] < 0.1 * h
        if drift.any():
            self._vdes[drift] *= rng.uniform(0.95, 1.05, int(drift.sum()))

    def _accelerations(self, h: float) -> None:
        """Accelerations held over the next step: IDM car following for vehicles (the ego is a
        leader too), P control of the speed otherwise, a lateral PD towards the target lane."""
        alive, kind, s, d, vx, vy = self._alive, self._kind, self._s, self._d, self._vx, self._vy
        veh = alive & (kind == VEHICLE)
        same = (np.abs(d[:, None] - d[None, :]) < 2.0) | (
            np.abs(self._dtgt[:, None] - d[None, :]) < 2.0)
        same &= veh[:, None] & veh[None, :]
        np.fill_diagonal(same, False)
        gaps = np.where(same & (s[None, :] > s[:, None]),
                        s[None, :] - s[:, None] - self._l[:, None], np.inf)
        lead = np.argmin(gaps, axis=1)
        gap, v_lead = gaps[np.arange(MAX_OBJECTS), lead], vx[lead]
        ego_gap = -EGO_LENGTH - s - self._l
        use = veh & (np.abs(d - self._e) < 2.0) & (s < -1.0) & (ego_gap < gap)
        gap, v_lead = np.where(use, ego_gap, gap), np.where(use, self._v, v_lead)
        v, v0 = np.maximum(vx, 0.0), np.maximum(self._vdes, 1.0)
        # the ego lane ahead hurries when the ego (driven by the host, never braking) comes close
        hurry = (self._lane_index(d) == 0) & (s > 0.0) & (vx < self._v + 1.0)
        a_max, headway = np.where(hurry, 2.5, 1.2), np.where(hurry, 0.9, 1.3)
        s_star = 3.0 + np.maximum(0.0, headway * v + v * (v - v_lead) / (2 * np.sqrt(a_max * 2.0)))
        a_idm = np.clip(a_max * (1 - (v / v0) ** 4 - (s_star / np.maximum(gap, 0.5)) ** 2), -6, 2.5)
        a_idm = np.maximum(a_idm, -v / max(h, 1e-3))  # stop, never reverse
        ax = np.where(kind == VEHICLE, a_idm, np.clip(
            np.where(kind == ONCOMING, 0.3, 0.5) * (self._vdes - vx), -1.0, 1.0))
        err = self._dtgt - d
        ay = np.where(kind <= ONCOMING, np.clip(0.8 * err - 1.6 * vy, -1.5, 1.5),
                      np.clip(0.5 * err - 1.0 * vy, -0.5, 0.5))
        self._ax = np.where(alive, ax, 0.0)
        self._ay = np.where(alive, ay, 0.0)

    # -- signs -------------------------------------------------------------------------------
    def _signs(self) -> None:
        s = self._sg_s
        gone = self._sg_alive & ((s < 8.0) | (s < np.abs(self._sg_lat) / math.tan(0.7)))
        for i in np.flatnonzero(gone):
            self._sg_alive[i] = False
            self._free_sign_ids.append(int(self._sg_id[i]))
        if self._s_e - self._next_sign > 1000.0:
            self._next_sign = self._s_e  # bounded: one sign, not one per 100 m skipped
        while self._s_e >= self._next_sign:  # a new sign every ~100 m: every 4 s at 25 m/s
            self._next_sign += float(self._rng.exponential(60.0)) + 40.0
            self._spawn_signs()

    def _spawn_signs(self) -> None:
        rng = self._rng
        names, codes, p = _sign_table()
        k = int(rng.choice(len(names), p=p))
        s = rng.uniform(70.0, 100.0)
        if names[k].startswith("e_lgt_"):  # electronic signs hang on a gantry over the lanes
            places = [(rng.uniform(-LANE_WIDTH, LANE_WIDTH), 5.5)]
        else:
            places = [(-(3 * HALF_LANE + rng.uniform(1.0, 2.5)), rng.uniform(1.8, 2.6))]
            if names[k][6:].isdigit() and rng.random() < 0.4:  # speed limits often in pairs
                places.append((3 * HALF_LANE + rng.uniform(0.8, 1.5), places[0][1]))
        for lat, z in places:
            free = np.flatnonzero(~self._sg_alive)
            if int(self._sg_alive.sum()) >= self._n_signs or len(free) == 0:
                return
            i = int(free[0])
            self._sg_alive[i] = True
            self._sg_id[i], self._sg_type[i] = self._free_sign_ids.popleft(), codes[k]
            self._sg_s[i], self._sg_lat[i], self._sg_z[i] = s, lat, z
            self._sg_bias[i] = rng.normal(0.0, 0.03)

    # -- derived obstacle state --------------------------------------------------------------
    def _lane_index(self, d: FArr) -> IArr:
        out: IArr = np.rint(d / LANE_WIDTH).astype(np.int64)
        return out

    def _cipv_distance(self) -> float:
        ego = self._alive & (self._lane_index(self._d) == 0) & (self._s > 0.0)
        return float(self._s[ego].min()) if ego.any() else math.inf

    def _columns(self) -> tuple[FArr, IArr, IArr]:
        """Rows of :data:`_OBJ_F` / :data:`_OBJ_I` for the live objects in id order, and their
        birth frames; computed once per step."""
        if self._cols is not None:
            return self._cols
        idx = np.flatnonzero(self._alive)
        idx = idx[np.argsort(self._oid[idx], kind="stable")]
        s, d, vx, vy, ax, ay = (a[idx] for a in (self._s, self._d, self._vx, self._vy,
                                                 self._ax, self._ay))
        w, length, hgt, kind = self._w[idx], self._l[idx], self._h[idx], self._kind[idx]
        c1, c2, c3 = self._poly[1:]
        y = self._lateral(s, d)
        vrel, a_s, ss = vx - self._v, np.abs(s), np.maximum(s, 0.5)
        speed = np.hypot(vx, vy)
        moving = speed >= 0.3
        road_heading = np.arctan(c1 + s * (2 * c2 + 3 * c3 * s))
        heading = np.where(moving, np.arctan2(vy, vx), 0.0) + road_heading
        heading = (heading + math.pi) % (2 * math.pi) - math.pi
        # §13.2.5.4: angles are measured from Z with "the positive side to the host's right";
        # y (latDistance) is left positive (ISO 8855), hence atan2(-y, ...)
        mid = np.arctan2(-y, ss)
        far = ss + length
        on_left, on_right = y > HALF_LANE, y < -HALF_LANE  # we see its right / left side
        side = np.where(on_left, np.arctan2(w / 2 - y, far),
                        np.where(on_right, np.arctan2(-y - w / 2, far), mid))
        ang_std = 0.002 + 5e-5 * a_s
        closing = -vrel
        ttc = np.where((s > 0.0) & (closing > 0.1),
                       np.minimum(s / np.maximum(closing, 0.1), TTC_NONE), TTC_NONE)
        age = self._frame_now - self._birth[idx] + 1
        conf = np.clip(0.97 - 0.0015 * a_s + self._cbias[idx]
                       - 0.2 * np.exp(-np.maximum(age, 1) / 6.0), 0.5, 1.0)
        f = np.array([
            w, 0.05 + 0.002 * a_s, length, 0.2 + 0.01 * a_s, hgt, 0.05 + 0.002 * a_s,
            vx, 0.1 + 0.01 * a_s, vy, 0.1 + 0.005 * a_s, ax, 0.2 + 0.004 * a_s,
            ay, 0.2 + 0.002 * a_s, s, 0.05 + 0.01 * a_s + 5e-5 * s * s, y, 0.05 + 0.003 * a_s,
            heading,
            np.arctan2(w / 2 - y, ss), ang_std, np.arctan2(-y - w / 2, ss), ang_std, side, ang_std,
            mid, ang_std, -(ss * vy - y * vrel) / (ss * ss + y * y), 0.005 + 1e-4 * a_s,
            conf, ttc], dtype=np.float64)
        # image: origin at the image centre, x right, y down (the rect is for visualisation)
        vis = s > 0.5
        u_l, u_r = -FOCAL_PX * (y + w / 2) / ss, -FOCAL_PX * (y - w / 2) / ss
        v_t, v_b = FOCAL_PX * (CAM_HEIGHT - hgt) / ss, FOCAL_PX * CAM_HEIGHT / ss
        side_vis = vis & (on_left | on_right)
        u_s = np.where(side_vis, -FOCAL_PX * np.where(on_left, y - w / 2, y + w / 2) / far, 0.0)
        v_ts = np.where(side_vis, FOCAL_PX * (CAM_HEIGHT - hgt) / far, 0.0)
        v_bs = np.where(side_vis, FOCAL_PX * CAM_HEIGHT / far, 0.0)
        zero = np.zeros(len(idx))
        lane = self._lane_index(d)
        lanes = np.array([_code("object_lane_assignment", n, v) for n, v in (
            ("RIGHT_NEXT_NEXT", 2), ("RIGHT_NEXT", 1), ("EGO_LANE", 0), ("LEFT_NEXT", -1),
            ("LEFT_NEXT_NEXT", -2))])
        lane_code = np.where(np.abs(lane) > 2, _code("object_lane_assignment", "UNKNOWN", 3),
                             lanes[np.clip(lane, -2, 2) + 2])
        vehicle = kind <= ONCOMING
        cipv = np.where(vehicle | (kind == CYCLIST), _code("object_is_cipv", "no_CIPV", 1),
                        _code("object_is_cipv", "not_relevant", 0))
        ahead = (lane == 0) & (s > 0.0)
        if ahead.any():
            cipv[int(np.argmin(np.where(ahead, s, np.inf)))] = _code("object_is_cipv", "CIPV", 2)
        err = self._dtgt[idx] - d
        signal = kind == VEHICLE
        i = np.array([
            u_l, u_r, v_t, v_b,
            u_l, v_t, v_b, zero, vis, u_r, v_t, v_b, zero, vis,
            u_s, v_ts, v_bs, zero, side_vis, zero, zero, zero, zero, zero,
            np.where(vis, np.where(vx < -0.5, _code("object_visible_rect", "Front", 1),
                                   _code("object_visible_rect", "Back", 2)), 0),
            np.where(vis & on_left, _code("object_visible_side", "Right", 1),
                     np.where(vis & on_right, _code("object_visible_side", "Left", 2), 0)),
            self._motion_status(speed, vehicle), self._motion_category(
                s, vx, vy, vrel, lane, kind, moving, d, self._dtgt[idx]),
            self._motion_orientation(vx, vy, moving),
            zero, self._oid[idx], self._cls_code[self._cls[idx]], cipv, lane_code,
            vehicle, signal & (ax < -1.0), signal & (err < -0.5), signal & (err > 0.5),
            zero, np.abs(d) < 3 * HALF_LANE + 0.5, (s < 3.0) & (np.abs(y) < 3.0)],
            dtype=np.float64)
        self._cols = (f, np.rint(i).astype(np.int64), self._birth[idx].copy())
        return self._cols

    @staticmethod
    def _motion_status(speed: FArr, vehicle: npt.NDArray[np.bool_]) -> IArr:
        c = _code
        out: IArr = _choose(
            [speed >= 2.0, speed >= 0.3, vehicle],
            [c("object_motion_status", "moving", 1), c("object_motion_status", "Moving_slowly", 4),
             c("object_motion_status", "Stopped", 3)], c("object_motion_status", "stationary", 2))
        return out

    @staticmethod
    def _motion_category(s: FArr, vx: FArr, vy: FArr, vrel: FArr, lane: IArr, kind: IArr,
                         moving: npt.NDArray[np.bool_], d: FArr, dtgt: FArr) -> IArr:
        def c(name: str, default: int) -> int:
            return _code("object_motion_category", name, default)

        changing = kind == VEHICLE
        out: IArr = _choose(
            [np.abs(vy) > np.maximum(np.abs(vx), 0.5), vx < -1.0,
             changing & (np.abs(dtgt) < np.abs(d) - 0.5),
             changing & (np.abs(dtgt) > np.abs(d) + 0.5),
             moving & (lane == 0) & (s > 0.0) & (vx > 0.5),
             moving & (lane != 0) & (vrel > 1.0) & (kind == VEHICLE), moving],
            [c("Crossing", 7), c("Oncoming", 12), c("Moving_in", 5), c("Moving_out", 6),
             c("Preceding", 11), c("Passing", 1), c("Moving", 10)], c("Undefined", 0))
        return out

    @staticmethod
    def _motion_orientation(vx: FArr, vy: FArr, moving: npt.NDArray[np.bool_]) -> IArr:
        def c(name: str, default: int) -> int:
            return _code("object_motion_orientation", name, default)

        crossing = np.abs(vy) > np.maximum(np.abs(vx), 0.5)
        oncoming = vx < -1.0
        out: IArr = _choose(
            [crossing & (vy > 0), crossing, oncoming & (vy > 0.3), oncoming & (vy < -0.3),
             oncoming, moving & (vy > 0.3), moving & (vy < -0.3), moving],
            [c("Crossing_left", 6), c("Crossing_right", 2), c("Oncoming_drifting_left", 5),
             c("Oncoming_drifting_right", 3), c("Oncoming", 4), c("Drifting_left", 7),
             c("Drifting_right", 1), c("Preceding", 8)], c("Unknown", 0))
        return out

    # -- payloads ----------------------------------------------------------------------------
    def fill(self, name: str, values: dict[str, Any], t: float) -> None:
        """Write the scene into a ``zero_values()`` dict of DASP message ``name`` (any SW
        version); members the layout lacks are skipped, unknown messages are left unchanged."""
        method = _FILLERS.get(name)
        if method is None:
            return
        last = self._nodes.get(name)
        if last is not None and last[0] is values:  # the caller reuses its dict: same layout
            node = last[1]
        else:
            node = _node_for(name, values)
            self._nodes[name] = (values, node)
        if node is None:
            return
        t = float(t)
        self._fill_header(values, node, t)
        for key, sub in node.members.items():
            if isinstance(sub, _Node) and sub.count is None and isinstance(values.get(key), dict):
                self._fill_header(values[key], sub, t)
        getattr(self, method)(values, node, t)

    def _fill_header(self, d: dict[str, Any], n: _Node, t: float) -> None:
        frame = _frame(t)
        _puts(d, n, {"timestamp_ms": int(t * 1000) & 0xFFFFFFFF,
                     "timestamp_us": max(0, round(t * 1e6)), "frameIndex": frame & 0xFFFFFFFF,
                     "imageIndex": frame & 0xFFFF, "vehIndexUsed": self._veh_index & 0xFFFFFFFF})

    def _fill_nothing(self, values: dict[str, Any], node: _Node, t: float) -> None:
        """Headers only (EYEQ_SAFETY_MSG: no safety fault, no challenge)."""

    def _fill_obstacles(self, values: dict[str, Any], node: _Node, t: float) -> None:
        vis = _child(values, node, "visObjects")
        if vis is None:
            return
        objs, elem = _elements(*vis, "visObs")
        if not objs:
            return
        plan = self._plans.get(id(elem))
        if plan is None:
            plan = self._plans[id(elem)] = _obj_plan(elem)
        f, i, birth = self._columns()
        n = min(f.shape[1], len(objs))
        i = i[:, :n].copy()
        i[_AGE_ROW] = np.maximum(_frame(t) - birth[:n] + 1, 1)
        fl = np.clip(f[:, :n], plan.flo[:, None], plan.fhi[:, None]).tolist()
        il = np.clip(i, plan.ilo[:, None], plan.ihi[:, None]).tolist()
        for path, items in plan.groups:
            probe: Any = objs[0]
            for p in path:
                ok = (isinstance(probe, dict) and p in probe) or (
                    isinstance(probe, list) and isinstance(p, int) and p < len(probe))
                probe = probe[p] if ok else None
            if not isinstance(probe, dict):
                continue
            cols = [(key, (fl if real else il)[row]) for key, real, row in items if key in probe]
            zeros = {key: 0.0 if real else 0 for key, real, _ in items if key in probe}
            for j, obj in enumerate(objs):
                target: Any = obj
                for p in path:
                    target = target[p]
                if j < n:
                    for key, col in cols:
                        target[key] = col[j]
                else:  # no object: id 0 marks the slot invalid (§13.2.2)
                    target.update(zeros)

    def _poly_values(self, offset: float, end: float) -> dict[str, float]:
        c0, c1, c2, c3 = self._poly
        return {"a0": c0 + offset, "a1": c1, "a2": c2, "a3": c3, "startRange": 5.0,
                "endRange": end}

    def _fill_marker(self, md: dict[str, Any], mn: _Node,
                     spec: tuple[float, str, float, float] | None) -> None:
        poly, conf = _child(md, mn, "laneMarker"), _child(md, mn, "laneMarkerConf")
        lmt = "lane_marker_type"
        if spec is None:  # §10.6: only seen with a wide separation between lanes
            if poly:
                _puts(*poly, dict.fromkeys(self._poly_values(0.0, 0.0), 0.0))
            if conf:
                _puts(*conf, {"sfConf": 0.0, "confidence": 0})
            _puts(md, mn, {"measuredViewRange": 0.0, "laneMarkerWidth": 0.0,
                           "laneMarkerType": _code(lmt, "INVALID", 6), "dlmType": 0,
                           "decelType": 0, "laneMarkerColor": 0})
            return
        offset, kind, view, phase = spec
        if poly:
            _puts(*poly, self._poly_values(offset, view))
        if conf:
            _puts(*conf, {"sfConf": 0.9 + 0.06 * math.sin(0.5 * self._tau + phase),
                          "confidence": _code("road_confidence_level", "Detected lanemark", 3)})
        _puts(md, mn, {
            "measuredViewRange": view * (0.85 if kind == "DASHED" else 0.95),
            "laneMarkerWidth": 0.12 if kind == "DASHED" else 0.15,
            "laneMarkerType": _code(lmt, kind, 0), "dlmType": _code("dlm_type", "NOTDLM", 0),
            "decelType": _code("decel_type", "NOTDECEL", 0),
            "laneMarkerColor": _code("lane_marker_color", "White", 1)})

    def _fill_road(self, values: dict[str, Any], node: _Node, t: float) -> None:
        info = _child(values, node, "roadInfo")
        if info is None:
            return
        rd, rn = info
        p = self._phase
        view = float(np.clip(min(105.0 + 12.0 * math.sin(0.2 * self._tau + p[2]),
                                 self._cipv_distance() + 25.0), 20.0, 128.0))
        markers: dict[str, tuple[float, str, float, float] | None] = {
            "hostLeftMarker": (HALF_LANE, "DASHED", view, p[3]),
            "hostRightMarker": (-HALF_LANE, "DASHED", view, p[4]),
            "nextLeftLeftMarker": (3 * HALF_LANE, "SOLID", 0.75 * view, p[5]),
            "nextRightRightMarker": (-3 * HALF_LANE, "SOLID", 0.75 * view, p[6]),
            "nextLeftRightMarker": None, "nextRightLeftMarker": None}
        mi = _child(rd, rn, "roadMarkerInfo")
        if mi:
            for key, spec in markers.items():
                m = _child(*mi, key)
                if m:
                    self._fill_marker(*m, spec)
            _puts(*mi, {"ambiguousLinePatternLeft": 0, "ambiguousLinePatternRight": 0,
                        "constructionArea": 0, "roadPredictionLeft": 0, "roadPredictionRight": 0})
        bi = _child(rd, rn, "roadBorderInfo")
        borders = (("leftRoadBorder", 3 * HALF_LANE + 0.8, "Barrier", 4, 0.8),
                   ("rightRoadBorder", -3 * HALF_LANE - 0.6, "Curb", 3, 0.15))
        for key, offset, kind, default, height in borders if bi else ():
            b = _child(*bi, key) if bi else None
            if b is None:
                continue
            poly, conf = _child(*b, "roadBorder"), _child(*b, "roadBorderConf")
            if poly:
                _puts(*poly, self._poly_values(offset, 0.6 * view))
            if conf:
                _puts(*conf, {"sfConf": 0.8, "confidence": _code(
                    "road_confidence_level", "Detected lanemark", 3)})
            _puts(*b, {"roadBorderHeight": height,
                       "roadBorderType": _code("road_border_type", kind, default)})
        hpp = _child(rd, rn, "roadHppFusionInfo")
        if hpp:
            centre = _child(*hpp, "laneCenter")
            if centre:
                _puts(*centre, self._poly_values(0.0, view))
            _puts(*hpp, {"roadFusionConf": 0.92, "halfWidth": HALF_LANE, "hppLeftWeight": 0.5,
                         "hppCenterWeight": 0.0, "hppRightWeight": 0.5, "roadLeftWeight": 0.5,
                         "roadRightWeight": 0.5})
        _puts(rd, rn, {"drivingSide": _code("road_driving_side", "Right Side", 0),
                       "laneChange": _code("road_lane_change", "No lane change", 0)})

    def _visible_signs(self) -> list[int]:
        idx = np.flatnonzero(self._sg_alive & (self._sg_s > 0.0))
        return [int(i) for i in idx[np.argsort(self._sg_s[idx], kind="stable")]]

    def _fill_signs(self, values: dict[str, Any], node: _Node, t: float) -> None:
        tsr = _child(values, node, "tsrInfo")
        if tsr is None:
            return
        elems, en = _elements(*tsr, "trafficSigns")
        rows: list[dict[str, float]] = []
        for i in self._visible_signs()[:len(elems)]:
            s, z = float(self._sg_s[i]), float(self._sg_z[i])
            y = float(self._lateral(self._sg_s[i:i + 1], self._sg_lat[i:i + 1])[0])
            ss = max(s, 1.0)
            u, v = IMAGE_W / 2 - FOCAL_PX * y / ss, IMAGE_H / 2 - FOCAL_PX * (z - CAM_HEIGHT) / ss
            half = FOCAL_PX * 0.35 / ss
            rows.append({
                # §16: "a positive value indicates the sign is on the right"
                "signLongPosition": s, "signLatPosition": -y, "signHeight": z,
                "signConfidence": min(1.0, 0.6 + 0.4 * (1.0 - s / 100.0) + self._sg_bias[i]),
                "signSuppConfidence1": 0.0, "signSuppConfidence2": 0.0,
                "relevancyConfidence": 0.95 if self._sg_lat[i] < 0.0 else 0.85,
                "signPositionBottom": v + half, "signPositionLeft": u - half,
                "signPositionRight": u + half, "signPositionTop": v - half,
                "signType": float(self._sg_type[i]), "signSupplementalType1": 0,
                "signSupplementalType2": 0, "signID": float(self._sg_id[i]),
                "signRelevantDecision": _code("tsr_sign_relevant_decision", "RELEVANT_SIGN", 0),
                "signFilterType": _code("tsr_sign_filter_type", "NO_SLI_FILTER", 0)})
        _write_rows(elems, en, rows, _SIGN_KEYS)
        _puts(*tsr, {"numberTrafficSigns": len(rows),
                     "currentMarket": _code("tsr_current_market", "EUROPE", 1)})
        marks = _child(*tsr, "roadMarkings")
        if marks:
            _puts(*marks, dict.fromkeys((
                "numberOfArrowsMarkings", "numberOfStopLinesMarkings",
                "numberOfSpeedLimitMarkings", "numberOfCrossingMarkings"), 0))

    def _fill_lights(self, values: dict[str, Any], node: _Node, t: float) -> None:
        info = _child(values, node, "activeLightSensorInfo")
        if info is None:
            return
        ld, ln = info
        cls = "light_spot_classification"
        spots, sn = _elements(ld, ln, "activeLightSpots")
        lit = np.flatnonzero(self._alive & (self._kind <= CYCLIST) & (self._s > 3.0))
        lit = lit[np.argsort(self._s[lit], kind="stable")][:min(self._n_spots, len(spots))]
        y_all = self._lateral(self._s, self._d)
        rows: list[dict[str, float]] = []
        oncoming_seen = False
        for i in (int(k) for k in lit):
            s, y, half = float(self._s[i]), float(y_all[i]), max(float(self._w[i]) / 2 - 0.15, 0.0)
            name, kind = CLASSES[int(self._cls[i])][0], int(self._kind[i])
            pair = name not in ("bike", "bicycle")
            oncoming_seen |= kind == ONCOMING
            code = (_code(cls, "Pair of Headlamps", 3) if kind == ONCOMING else
                    _code(cls, "Pair of Tail-lamps", 4) if pair else _code(cls, "Tail-lamp", 2))
            # §15 light spots: "angles to the right of the sensor coordinate system are
            # positive", "angle below the horizon are positive"; pixels from the image's left
            # bottom corner
            left, right = math.atan2(-y - half, s), math.atan2(half - y, s)
            top, bottom = math.atan2(CAM_HEIGHT - 1.0, s), math.atan2(CAM_HEIGHT - 0.6, s)
            rows.append({
                "leftAngle": left, "rightAngle": right, "topAngle": top, "bottomAngle": bottom,
                "id": float(self._oid[i]), "vdID": float(self._oid[i]), "longPos": s,
                "pixelTop": IMAGE_H / 2 - FOCAL_PX * math.tan(top),
                "pixelBottom": IMAGE_H / 2 - FOCAL_PX * math.tan(bottom),
                "pixelLeft": IMAGE_W / 2 + FOCAL_PX * math.tan(left),
                "pixelRight": IMAGE_W / 2 + FOCAL_PX * math.tan(right),
                "classification": code, "isTruck": float(name == "truck")})
        _write_rows(spots, sn, rows, _SPOT_KEYS)
        signs, gn = _elements(ld, ln, "reflectiveSigns")
        refl: list[dict[str, float]] = []
        for i in self._visible_signs()[:len(signs)]:
            s, z = float(self._sg_s[i]), float(self._sg_z[i]) - CAM_HEIGHT
            y = float(self._lateral(self._sg_s[i:i + 1], self._sg_lat[i:i + 1])[0])
            glare = 100.0 * math.exp(-s / 50.0)
            refl.append({
                "lightSignLeftAngle": math.atan2(-y - 0.4, s),  # §15: "Negative: left"
                "lightSignRightAngle": math.atan2(0.4 - y, s),
                "lightSignBottomAngle": math.atan2(z - 0.4, s),
                "lightSignTopAngle": math.atan2(z + 0.4, s), "lightSignID": float(self._sg_id[i]),
                "lightSignDistance": s, "lightSignGlareLevelMax": min(100.0, glare + 10.0),
                "lightSignGlareLevelCurrent": glare})
        _write_rows(signs, gn, refl, _REFLECT_KEYS)
        _puts(ld, ln, {
            "ahbcAvailable": _code("ahbc_available", "Full", 2),
            "gridFrequency": _code("ahbc_grid_frequency", "50 Hz", 1),
            "numOfActiveLightSpots": len(rows), "numOfReflectiveSigns": len(refl),
            "clearFieldOfView": _code("ahbc_clear_field_of_view", "No Clear Field-Of-View", 1)
            if rows else _code("ahbc_clear_field_of_view", "Clear Field-Of-View", 2),
            "beamRequest": _code("ahbc_beam_request", "OFF" if rows else "ON", 0 if rows else 1),
            "inTunnel": _code("ahbc_in_tunnel", "FALSE", 1), "eventsDetected": 0,
            "fogDetected": 0, "highwayDetected": 1, "villageDetected": 0,
            "oncomingLaneNotDark": int(oncoming_seen), "approachingJunction": 0,
            "lightNoisyScene": 0, "lightCone": 0})

    def _fill_aeb(self, values: dict[str, Any], node: _Node, t: float) -> None:
        aeb = _child(values, node, "visAEB")
        if aeb:  # vision-only AEB stays quiet: the ego never closes in dangerously
            _puts(*aeb, {k: 0 for k in aeb[1].members if k.startswith("visOnly")})
            _puts(*aeb, {"roadFreeDetection": _code(
                "aeb_road_free_detection", "NO_PENETRATION_DETECTED", 0)})

    def _fill_failsafe(self, values: dict[str, Any], node: _Node, t: float) -> None:
        fs = _child(values, node, "visFailsafes")
        if fs:
            none = _code("failsafe_severity", "NONE", 1)
            _puts(*fs, {k: none for k in fs[1].members if k.endswith("SeverityLevel")})
            _puts(*fs, {"freeSight": _code("free_sight", "TRUE", 1), "outOfCalibTSR": 0})

    def _fill_srp(self, values: dict[str, Any], node: _Node, t: float) -> None:
        srp = _child(values, node, "visSRP")
        if srp is None:
            return
        for key, phase in (("leftWheelDataPoints", self._phase[0]),
                           ("rightWheelDataPoints", self._phase[1])):
            elems, en = _elements(*srp, key)
            rows: list[dict[str, float]] = []
            for k in range(len(elems)):  # road profile under each wheel, 5..32 m ahead
                pos = self._s_e + 5.0 + 3.0 * k
                rows.append({"height": 0.8 * math.sin(2 * math.pi * pos / 37.0 + phase)
                             + 0.4 * math.sin(2 * math.pi * pos / 11.3 + 2 * phase),
                             "conf": 15 - k})
            _write_rows(elems, en, rows, ("height", "conf"))
        _puts(*srp, {"vehicleVelocity": self._v, "frameValid": 1})

    def _fill_timesync(self, values: dict[str, Any], node: _Node, t: float) -> None:
        ts = _child(values, node, "timeSyncData")
        if ts:
            _puts(*ts, {"Frame_MCU_TS_Start": max(0, round((t - 0.03) * 1e6)),
                        "Last_MCU_Sync_TS": math.floor(t) * 1_000_000,
                        "Last_Clock_Sync_Skew": 0})

    def _fill_dynamic_cal(self, values: dict[str, Any], node: _Node, t: float) -> None:
        cal = _child(values, node, "dynamicCalParams")
        if cal is None:
            return
        progress = min(100.0, 10.0 * self._tau)
        yaw = 0.25 + 0.02 * math.sin(0.05 * self._tau)
        pitch = -0.4 + 0.02 * math.sin(0.07 * self._tau + 1.0)
        _puts(*cal, {
            "phYaw": yaw, "phPitch": pitch, "roll": 0.1, "camHeight": CAM_HEIGHT,
            "reserved": CAM_HEIGHT, "distYaw": FOCAL_PX * math.tan(math.radians(yaw)),
            "distPitch": FOCAL_PX * math.tan(math.radians(pitch)),
            "runMode": _code("dynamic_cal_run_mode", "AUTOFIX", 4),
            "status": _code("dynamic_cal_status", "SUCCESS" if progress >= 100 else "INIT",
                            1 if progress >= 100 else 0),
            "error": _code("dynamic_cal_error", "OK", 3), "overallProgress": progress})
