"""The world of the simulated EyeQ's driving scene: road, objects, signs and their dynamics.

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
objects and signs all use that one polynomial, so they agree with each other. All randomness
is drawn in :meth:`SceneWorld.step` from one ``np.random.Generator``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from eyeq_spi.sim.scene_layout import (
    CLASS_P,
    CLASSES,
    CYCLIST,
    DXS,
    EGO_LENGTH,
    EGO_SPEED_MAX,
    EGO_SPEED_MIN,
    HALF_LANE,
    LANE_WIDTH,
    MAX_GAP,
    MAX_OBJECTS,
    MAX_SIGNS,
    MAX_SPOTS,
    MAX_SUBSTEP,
    ONCOMING,
    PEDESTRIAN,
    PINV,
    VEHICLE,
    XS,
    FArr,
    IArr,
    cumtrapz,
    frame_index,
    sign_table,
)

# per kind (VEHICLE, ONCOMING, CYCLIST, PEDESTRIAN): where an object leaves, behind and ahead
_BEHIND = np.array([-30.0, -20.0, -15.0, -10.0])
_AHEAD = np.array([200.0, 200.0, 130.0, 95.0])
_ROWS = np.arange(MAX_OBJECTS)
_OTHERS = ~np.eye(MAX_OBJECTS, dtype=bool)  # pairs of two different objects


@dataclass
class SceneConfig:
    seed: int = 1
    objects: int = 8  # 0..15 tracked objects (E_EYEQ_MAX_VISION_OBJECTS = 15)
    signs: int = 4  # 0..20 traffic signs visible at a time
    light_spots: int = 4  # 0..15
    ego_speed: float = 25.0  # m/s, default constant-speed drive
    # light-spot topAngle/bottomAngle count above the horizon positive in the SW4.0+ table
    # (seed 004 lines 3294-3295), below the horizon in the earlier ones (lines 3256-3257, 3273-3274)
    spot_angles_up: bool = True


class SceneWorld:
    """The world (objects, road, signs) and its dynamics, which :class:`eyeq_spi.sim.scene.Scene`
    reports; road coordinates ``s``, ``d`` and the ego's speed ``v`` as in the module docstring."""

    def __init__(self, config: SceneConfig | None = None) -> None:
        self.config = cfg = config or SceneConfig()
        self._rng = rng = np.random.default_rng(cfg.seed)
        self._n_obj = int(min(max(cfg.objects, 0), MAX_OBJECTS))
        self._n_signs = int(min(max(cfg.signs, 0), MAX_SIGNS))
        self.n_spots = int(min(max(cfg.light_spots, 0), MAX_SPOTS))
        self._t: float | None = None
        self.tau = 0.0  # s since the first step
        self.v = float(cfg.ego_speed)
        self._v_host: float | None = None
        self._k_host: float | None = None
        self.s_e = 0.0  # distance the ego has driven
        self._e = 0.0  # ego offset from its lane centre, left positive
        self.veh_index = 0
        self.frame_now = 0
        self.phase = rng.uniform(0.0, 2 * math.pi, 8)
        self.poly = (0.0, 0.0, 0.0, 0.0)
        self._knot_s, self._knot_k = [-200.0, 0.0], [0.0, 0.0]
        self._extend_road()
        slots = MAX_OBJECTS
        self.alive = np.zeros(slots, dtype=bool)
        self.oid, self.cls, self.kind, self.birth = (
            np.zeros(slots, np.int64) for _ in range(4))
        self.s, self.d, self.vx, self.vy, self.ax, self.ay = (
            np.zeros(slots) for _ in range(6))
        self.width, self.length, self.height, self._vdes, self.dtgt, self.cbias = (
            np.zeros(slots) for _ in range(6))
        self._free_ids: deque[int] = deque(range(1, MAX_OBJECTS + 1))
        sign_slots = MAX_SIGNS
        self.sg_alive = np.zeros(sign_slots, dtype=bool)
        self.sg_id, self.sg_type = (np.zeros(sign_slots, np.int64) for _ in range(2))
        self.sg_s, self.sg_lat, self.sg_z, self.sg_bias = (
            np.zeros(sign_slots) for _ in range(4))
        self._free_sign_ids: deque[int] = deque(range(MAX_SIGNS))
        self._next_sign = float(rng.exponential(60.0)) + 20.0
        for index in range(self._n_obj):
            self._spawn(initial=True, first=index == 0)
        self._update_road(None, 0.0)

    def unanchor(self) -> None:
        """Forget the time of the last step (after a warm-up): the next step anchors the scene
        in time as the first one does."""
        self._t = None

    # -- time --------------------------------------------------------------------------------
    def step(self, t: float, ego_speed: float | None = None, yaw_rate: float | None = None) -> bool:
        """Advance the world to virtual time ``t`` (s, monotonic); ego state from the host's
        HOST_VEH_STATE_MSG when known, else the last known speed (or ``config.ego_speed``).
        Returns whether the world moved (or was anchored in time)."""
        t = float(t)
        if not math.isfinite(t):
            return False
        if ego_speed is not None and math.isfinite(ego_speed):
            self.veh_index += 1
            # §7.1.2.2 vehicleVelocity range: no input may make a step unbounded
            self._v_host = min(max(float(ego_speed), EGO_SPEED_MIN), EGO_SPEED_MAX)
        v_target = self._v_host if self._v_host is not None else float(self.config.ego_speed)
        yaw = None if yaw_rate is None or not math.isfinite(yaw_rate) else float(yaw_rate)
        if self._t is None:  # the first step anchors the scene in time
            self._t, self.frame_now, self.v = t, frame_index(t), v_target
            self.birth[self.alive] += self.frame_now
            self._update_road(yaw, 0.0)
            return True
        dt = t - self._t
        if dt <= 0.0:
            return False
        skip = max(0.0, dt - MAX_GAP)
        substeps = max(1, math.ceil((dt - skip) / MAX_SUBSTEP - 1e-9))
        h, v0 = (dt - skip) / substeps, self.v
        self.tau += skip
        for substep in range(substeps):
            va = v0 + (v_target - v0) * substep / substeps
            vb = v0 + (v_target - v0) * (substep + 1) / substeps
            self._integrate(h, va, vb)
            self.tau += h
            self.v = vb
            self.frame_now = frame_index(self._t + skip + (substep + 1) * h)
            self._update_road(yaw, h)
            self._decide(h)
        self._t = t
        return True

    def _integrate(self, h: float, va: float, vb: float) -> None:
        """§7.1 constant-acceleration process model over ``h`` seconds, relative to the ego."""
        disp = 0.5 * (va + vb) * h
        self.s += self.vx * h + 0.5 * self.ax * h * h - disp
        self.vx += self.ax * h
        self.d += self.vy * h + 0.5 * self.ay * h * h
        self.vy += self.ay * h
        self.sg_s -= disp
        self.s_e += disp

    def _decide(self, h: float) -> None:
        self._despawn()
        while int(self.alive.sum()) < self._n_obj and self._spawn():
            pass
        self._lane_changes(h)
        self._accelerations(h)
        self._signs()

    # -- road --------------------------------------------------------------------------------
    def _extend_road(self) -> None:
        """§7.2 clothoids: curvature linear in arc length between straights and gentle arcs."""
        rng = self._rng
        if self._knot_s[-1] < self.s_e - 1000.0:
            # far behind (a jump in time or distance): restart the road at the ego instead of
            # generating every kilometre in between; keeps each step bounded
            self._knot_s = [self.s_e - 300.0, self.s_e - 100.0]
            self._knot_k = [self._knot_k[-1], self._knot_k[-1]]
        while self._knot_s[-1] < self.s_e + 400.0:
            straight = rng.random() < 0.4
            target = 0.0 if straight else float(np.clip(rng.normal(0.0, 0.001), -0.003, 0.003))
            s0, l1, l2 = self._knot_s[-1], rng.uniform(80.0, 200.0), rng.uniform(100.0, 400.0)
            self._knot_s += [s0 + l1, s0 + l1 + l2]
            self._knot_k += [target, target]
        while len(self._knot_s) > 3 and self._knot_s[1] < self.s_e - 200.0:
            del self._knot_s[0], self._knot_k[0]

    def _update_road(self, yaw_rate: float | None, h: float) -> None:
        self._extend_road()
        k = np.interp(self.s_e + XS, self._knot_s, self._knot_k)
        if yaw_rate is not None and abs(self.v) > 1.0:
            # the host's yaw rate says how the road bends where the ego is
            target = min(max(yaw_rate / self.v, -0.008), 0.008)  # np.clip of one float
            kh = self._k_host
            kh = target if kh is None else kh + (target - kh) * min(1.0, h / 0.5)
            self._k_host = kh
            k = k - k[0] + kh
        else:
            self._k_host = None
        y = cumtrapz(cumtrapz(k, DXS), DXS)
        c2, c3 = (float(c) for c in PINV @ y)
        p, tau = self.phase, self.tau
        w1, w2 = 2 * math.pi / 14.0, 2 * math.pi / 4.3
        self._e = 0.15 * math.sin(w1 * tau + p[0]) + 0.05 * math.sin(w2 * tau + p[1])
        e_dot = 0.15 * w1 * math.cos(w1 * tau + p[0]) + 0.05 * w2 * math.cos(w2 * tau + p[1])
        # min(max()) is np.clip on one float (NaN kept), without numpy's call overhead
        c1 = min(max(-e_dot / max(abs(self.v), 1.0), -0.05), 0.05)
        self.poly = (-self._e, c1, min(max(c2, -0.0099), 0.0099),
                      min(max(c3, -1.69e-4), 1.69e-4))

    def lateral(self, s: FArr, d: FArr) -> FArr:
        """Road (s, d) -> lateral distance in the ego frame through the road polynomial."""
        c0, c1, c2, c3 = self.poly
        out: FArr = d + c0 + s * (c1 + s * (c2 + s * c3))
        return out

    # -- objects -----------------------------------------------------------------------------
    def _clear(self, s: float, d: float, length: float) -> bool:
        if abs(d - self._e) < 2.5 and -EGO_LENGTH - 15.0 < s < 15.0:
            return False
        there = (np.abs(self.d - d) < 2.5) | (np.abs(self.dtgt - d) < 2.5)
        near = self.alive & there & (np.abs(self.s - s) < 15.0 + np.maximum(length, self.length))
        return not bool(near.any())

    def _place(self, name: str, kind: int, initial: bool, first: bool
               ) -> tuple[float, float, float]:
        """One candidate (s, d, target speed) for a new object of class ``name``."""
        rng, v_e = self._rng, max(self.v, 0.0)
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
        free = (~self.alive).nonzero()[0]
        if len(free) == 0 or not self._free_ids:
            return False
        slot, rng = int(free[0]), self._rng
        ci = 0 if first else int(rng.choice(len(CLASSES), p=CLASS_P))
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
        self.alive[slot] = True
        self.oid[slot] = self._free_ids.popleft()
        self.cls[slot], self.kind[slot] = ci, kind
        self.s[slot], self.d[slot], self.dtgt[slot] = s, d, d
        self.vx[slot], self._vdes[slot] = vdes, vdes
        self.vy[slot] = self.ax[slot] = self.ay[slot] = 0.0
        self.width[slot] = float(np.clip(w * rng.normal(1.0, 0.04), 0.45, 2.9))
        spread = 0.2 if name == "truck" else 0.06
        self.length[slot] = float(np.clip(length * rng.normal(1.0, spread), 0.45, 18.5))
        self.height[slot] = float(np.clip(hgt * rng.normal(1.0, 0.04), 0.5, 4.0))
        self.cbias[slot] = rng.normal(0.0, 0.015)
        self.birth[slot] = self.frame_now - (int(rng.integers(0, 300)) if initial else 0)
        return True

    def _despawn(self) -> None:
        s, kind = self.s, self.kind
        far = (s < _BEHIND[kind]) | (s > _AHEAD[kind])  # leaves the range of its kind
        # an object the ego drives into is lost rather than driven through
        hit = (np.abs(self.d - self._e) < 1.6) & (s > -EGO_LENGTH - 1.0) & (s < 1.0)
        for slot in np.flatnonzero(self.alive & (far | (hit & (kind != ONCOMING)))):
            self.alive[slot] = False
            self._free_ids.append(int(self.oid[slot]))
            self.oid[slot] = 0

    def _change_lane(self, slot: int, lane: int, escape: bool = False) -> bool:
        s, target = float(self.s[slot]), lane * LANE_WIDTH
        if not -1 <= lane <= 1 or (lane == 0 and not escape and -40.0 < s < 30.0):
            return False
        others = self.alive.copy()
        others[slot] = False
        there = (np.abs(self.d - target) < 2.5) | (np.abs(self.dtgt - target) < 0.5)
        gap = (6.0 if escape else 15.0) + np.maximum(self.length[slot], self.length)
        busy = others & there & (np.abs(self.s - s) < gap)
        if busy.any():
            return False
        self.dtgt[slot] = target
        return True

    def _lane_changes(self, h: float) -> None:
        rng, v_e, s = self._rng, self.v, self.s
        steady = self.alive & (self.kind == VEHICLE) & (np.abs(self.dtgt - self.d) <= 0.3)
        lane = self.lane_index(self.dtgt)
        closing = v_e - self.vx
        # the ego closes in on it: it gets out of the way or speeds up
        escape = steady & (lane == 0) & (s > -1.0) & (closing > 0.5) & (
            (s < 10.0 * closing) | (s < 0.8 * v_e + 5.0))
        draws = rng.random((3, MAX_OBJECTS))
        for slot in (int(k) for k in escape.nonzero()[0]):
            if not (self._change_lane(slot, -1, True) or self._change_lane(slot, 1, True)):
                # boxed in: the whole ego lane ahead speeds up
                platoon = self.alive & (self.kind == VEHICLE) & (s > -1.0) & (
                    (lane == 0) | (self.lane_index(self.d) == 0))
                self._vdes[platoon] = np.maximum(self._vdes[platoon], v_e + 3.0)
        for slot in (int(k) for k in (steady & ~escape & (draws[0] < 0.03 * h)).nonzero()[0]):
            self._change_lane(slot, int(lane[slot]) + (1 if draws[1, slot] < 0.5 else -1))
        drift = draws[2] < 0.1 * h
        if drift.any():
            self._vdes[drift] *= rng.uniform(0.95, 1.05, int(drift.sum()))

    def _accelerations(self, h: float) -> None:
        """Accelerations held over the next step: IDM car following for vehicles (the ego is a
        leader too), P control of the speed otherwise, a lateral PD towards the target lane."""
        alive, kind, s, d, vx, vy = self.alive, self.kind, self.s, self.d, self.vx, self.vy
        veh = alive & (kind == VEHICLE)
        same = (np.abs(d[:, None] - d[None, :]) < 2.0) | (
            np.abs(self.dtgt[:, None] - d[None, :]) < 2.0)
        same &= (veh[:, None] & veh[None, :]) & _OTHERS  # not itself
        gaps = np.where(same & (s[None, :] > s[:, None]),
                        s[None, :] - s[:, None] - self.length[:, None], np.inf)
        lead = gaps.argmin(axis=1)
        gap, v_lead = gaps[_ROWS, lead], vx[lead]
        ego_gap = -EGO_LENGTH - s - self.length
        use = veh & (np.abs(d - self._e) < 2.0) & (s < -1.0) & (ego_gap < gap)
        gap, v_lead = np.where(use, ego_gap, gap), np.where(use, self.v, v_lead)
        v, v0 = np.maximum(vx, 0.0), np.maximum(self._vdes, 1.0)
        # the ego lane ahead hurries when the ego (driven by the host, never braking) comes close
        hurry = (self.lane_index(d) == 0) & (s > 0.0) & (vx < self.v + 1.0)
        a_max, headway = np.where(hurry, 2.5, 1.2), np.where(hurry, 0.9, 1.3)
        s_star = 3.0 + np.maximum(0.0, headway * v + v * (v - v_lead) / (2 * np.sqrt(a_max * 2.0)))
        a_idm = np.clip(a_max * (1 - (v / v0) ** 4 - (s_star / np.maximum(gap, 0.5)) ** 2), -6, 2.5)
        a_idm = np.maximum(a_idm, -v / max(h, 1e-3))  # stop, never reverse
        ax = np.where(kind == VEHICLE, a_idm, np.clip(
            np.where(kind == ONCOMING, 0.3, 0.5) * (self._vdes - vx), -1.0, 1.0))
        err = self.dtgt - d
        ay = np.where(kind <= ONCOMING, np.clip(0.8 * err - 1.6 * vy, -1.5, 1.5),
                      np.clip(0.5 * err - 1.0 * vy, -0.5, 0.5))
        self.ax = np.where(alive, ax, 0.0)
        self.ay = np.where(alive, ay, 0.0)

    # -- signs -------------------------------------------------------------------------------
    def _signs(self) -> None:
        s = self.sg_s
        gone = self.sg_alive & ((s < 8.0) | (s < np.abs(self.sg_lat) / math.tan(0.7)))
        for slot in gone.nonzero()[0]:
            self.sg_alive[slot] = False
            self._free_sign_ids.append(int(self.sg_id[slot]))
        if self.s_e - self._next_sign > 1000.0:
            self._next_sign = self.s_e  # bounded: one sign, not one per 100 m skipped
        while self.s_e >= self._next_sign:  # a new sign every ~100 m: every 4 s at 25 m/s
            self._next_sign += float(self._rng.exponential(60.0)) + 40.0
            self._spawn_signs()

    def _spawn_signs(self) -> None:
        rng = self._rng
        names, codes, weights = sign_table()
        choice = int(rng.choice(len(names), p=weights))
        s = rng.uniform(70.0, 100.0)
        if names[choice].startswith("e_lgt_"):  # electronic signs hang on a gantry over the lanes
            places = [(rng.uniform(-LANE_WIDTH, LANE_WIDTH), 5.5)]
        else:
            places = [(-(3 * HALF_LANE + rng.uniform(1.0, 2.5)), rng.uniform(1.8, 2.6))]
            if names[choice][6:].isdigit() and rng.random() < 0.4:  # speed limits often in pairs
                places.append((3 * HALF_LANE + rng.uniform(0.8, 1.5), places[0][1]))
        for lat, z in places:
            free = (~self.sg_alive).nonzero()[0]
            if int(self.sg_alive.sum()) >= self._n_signs or len(free) == 0:
                return
            slot = int(free[0])
            self.sg_alive[slot] = True
            self.sg_id[slot], self.sg_type[slot] = self._free_sign_ids.popleft(), codes[choice]
            self.sg_s[slot], self.sg_lat[slot], self.sg_z[slot] = s, lat, z
            self.sg_bias[slot] = rng.normal(0.0, 0.03)

    # -- derived obstacle state --------------------------------------------------------------
    def lane_index(self, d: FArr) -> IArr:
        out: IArr = np.rint(d / LANE_WIDTH).astype(np.int64)
        return out

    def cipv_distance(self) -> float:
        ego = self.alive & (self.lane_index(self.d) == 0) & (self.s > 0.0)
        return float(self.s[ego].min()) if ego.any() else math.inf
