"""Decoded messages and events in, Foxglove topics out (:mod:`eyeq_spi.foxglove.topics`).

:class:`Feed` is the one translation, fed by a capture's dissector records (:class:`RecordFeed`,
``export --mcap``) or by a running host (:mod:`eyeq_spi.foxglove.live`). Times are seconds on
the caller's base (a capture's timestamps, or the run's clock); a sink gets them in ns.

- a scene message (obstacles, road, signs, light spots) without decode errors becomes one
  SceneUpdate on its topic (E2E and counter errors alone do not hide it, as in every view);
- HOST_VEH_STATE_MSG's ``vehicleVelocity`` and ``vehicleYawRate`` become ``/ego`` and the
  dead-reckoned ``odom`` -> ``vehicle`` transform, sent on ``/tf`` with every obstacles update;
- every second: ``/streams`` (the rates of the last second) and ``/link/ack_latency``;
- :meth:`Feed.log`: a line on ``/log``.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.foxglove import topics
from eyeq_spi.foxglove.scene import KINDS, SceneMessages, fg, frame_transforms, timestamp
from eyeq_spi.plot.perceived import OBSTACLES, Labels, SceneTracker
from eyeq_spi.plot.vehicle_frame import CAMERA_HEIGHT_M
from eyeq_spi.summary import ack_latency_ms

VEH_STATE = "HOST_VEH_STATE_MSG"
STATS_PERIOD_S = 1.0
LEVELS = ("debug", "info", "warning", "error")


def ns(t: float) -> int:
    return max(0, round(t * 1e9))


def _find(fields: Any, key: str) -> float | None:
    """The first number named ``key`` anywhere in decoded fields (every release's layout)."""
    if isinstance(fields, dict):
        value = fields.get(key)
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value)
        for inner in fields.values():
            if isinstance(inner, dict | list):
                found = _find(inner, key)
                if found is not None:
                    return found
    elif isinstance(fields, list):
        for inner in fields:
            found = _find(inner, key)
            if found is not None:
                return found
    return None


def schemas() -> dict[str, Any]:
    """Every topic with its schema: a ``foxglove.messages`` class or a JSON Schema (what a live
    server advertises before the first message)."""
    m = fg()
    out: dict[str, Any] = dict.fromkeys(topics.SCENE_TOPICS.values(), m.SceneUpdate)
    out.update({topics.TF: m.FrameTransform, topics.LOG: m.Log, topics.EGO: topics.EGO_SCHEMA,
                topics.STREAMS: topics.STREAMS_SCHEMA, topics.ACK_LATENCY: topics.ACK_SCHEMA})
    return out


class DeadReckoning:
    """The vehicle's pose in ``odom`` from its speed and yaw rate (x, y in m, yaw in rad)."""

    def __init__(self) -> None:
        self.x = self.y = self.yaw = 0.0
        self.last: float | None = None

    def step(self, t: float, speed: float, yaw_rate: float) -> None:
        if self.last is not None and 0.0 < t - self.last < 1.0:  # a gap or a jump: hold
            dt = t - self.last
            self.yaw = math.remainder(self.yaw + yaw_rate * dt, math.tau)
            self.x += speed * math.cos(self.yaw) * dt
            self.y += speed * math.sin(self.yaw) * dt
        self.last = t

    def pose(self) -> tuple[float, float, float] | None:
        return None if self.last is None else (self.x, self.y, self.yaw)


class Feed:
    """The Foxglove topics of one run or capture, written to ``sink``."""

    def __init__(self, codec: MessageCodec, sink: topics.Sink, *,
                 camera_height: float = CAMERA_HEIGHT_M) -> None:
        self.sink = sink
        self.tracker = SceneTracker(Labels(codec))
        rates = {}
        for kind in KINDS:
            try:
                rates[kind] = codec.cat.message(kind).rate_hz or 0.0
            except Exception:
                rates[kind] = 0.0
        self.camera_height = camera_height
        self.scenes = SceneMessages(rates, camera_height)
        self.odom = DeadReckoning()
        self.counts: Counter[str] = Counter()  # messages received since the last /streams
        self.acks: Counter[int] = Counter()  # 10 µs bin -> DATA frames ACKed, this second
        self.next_stats: float | None = None
        self.published: Counter[str] = Counter()  # topic -> messages written

    def message(self, name: str | None, fields: dict[str, Any] | None, t: float | None,
                errors: list[str] | tuple[str, ...] = ()) -> None:
        """One decoded message, as the host or the dissector delivered it."""
        if t is None or name is None:
            return
        if name == VEH_STATE and fields and not errors:
            self._ego(fields, t)
        elif name in topics.SCENE_TOPICS and self.tracker.update(name, fields, t, errors):
            self._scene(name, t)
        self.tick(t)

    def _scene(self, name: str, t: float) -> None:
        stamp = ns(t)
        self._put(topics.SCENE_TOPICS[name],
                  self.scenes.update(name, self.tracker.scene, stamp), stamp)
        if name == OBSTACLES:
            for tf in frame_transforms(stamp, self.odom.pose(), self.camera_height):
                self._put(topics.TF, tf, stamp)

    def _ego(self, fields: dict[str, Any], t: float) -> None:
        speed, yaw_rate = _find(fields, "vehicleVelocity"), _find(fields, "vehicleYawRate")
        if speed is None or yaw_rate is None:
            return
        self.ego(speed, yaw_rate, t)

    def ego(self, speed: float, yaw_rate: float, t: float) -> None:
        """The ego vehicle's speed (m/s) and yaw rate (rad/s, left positive) at ``t``."""
        self.odom.step(t, speed, yaw_rate)
        self._values(topics.EGO, topics.EGO_SCHEMA, {"speed": speed, "yaw_rate": yaw_rate}, t)

    def received(self, name: str, t: float) -> None:
        """A message counted for ``/streams`` without its fields (a live host's traffic)."""
        self.counts[name] += 1
        self.tick(t)

    def ack(self, latency: float, t: float) -> None:
        """One DATA frame's send -> ACK time, seconds."""
        self.acks[int(latency * 1e5)] += 1
        self.tick(t)

    def ack_bins(self, bins: Counter[int], t: float) -> None:
        """ACK latencies as a link counts them (10 µs bins)."""
        self.acks.update(bins)
        self.tick(t)

    def log(self, text: str, t: float, level: str = "info", name: str = "eyeq-spi") -> None:
        m = fg()
        stamp = ns(t)
        lvl = {"debug": m.LogLevel.Debug, "info": m.LogLevel.Info,
               "warning": m.LogLevel.Warning, "error": m.LogLevel.Error}[level]
        self._put(topics.LOG, m.Log(timestamp=timestamp(stamp), level=lvl, message=text,
                                    name=name), stamp)

    def tick(self, t: float) -> None:
        """Publish the once-a-second topics when their second is over."""
        if self.next_stats is None:
            self.next_stats = t + STATS_PERIOD_S
        if t < self.next_stats:
            return
        span = STATS_PERIOD_S + max(0.0, t - self.next_stats)
        if self.counts:
            self._values(topics.STREAMS, topics.STREAMS_SCHEMA,
                         {k: round(v / span, 2) for k, v in sorted(self.counts.items())}, t)
        if self.acks:
            stats = ack_latency_ms(self.acks)
            self._values(topics.ACK_LATENCY, topics.ACK_SCHEMA,
                         {"p50_ms": stats["p50"], "max_ms": stats["max"], "n": stats["n"]}, t)
        self.counts.clear()
        self.acks.clear()
        self.next_stats = t + STATS_PERIOD_S

    def _put(self, topic: str, msg: Any, stamp: int) -> None:
        self.sink.message(topic, msg, stamp)
        self.published[topic] += 1

    def _values(self, topic: str, schema: dict[str, Any], body: dict[str, Any],
                t: float) -> None:
        self.sink.values(topic, schema, body, ns(t))
        self.published[topic] += 1


class RecordFeed:
    """A capture's dissector records (``eyeq-spi dissect``'s) into a :class:`Feed`: its decoded
    messages, its link and transport events and message errors as log lines, and the ACK
    latency of every DATA frame matched to the ACK that answers it."""

    def __init__(self, feed: Feed) -> None:
        self.feed = feed
        self.sent: dict[tuple[str | None, int], float] = {}  # (direction, NUM) -> DATA time
        self.last_time: float | None = None

    def add(self, record: dict[str, Any]) -> None:
        kind = record["kind"]
        t = record.get("time")
        if t is not None:
            self.last_time = t
        if kind == "message":
            if t is not None:
                self.feed.received(record["name"] or record["protocol"], t)
            self.feed.message(record["name"], record["fields"], t, record["errors"])
            for error in record["errors"]:
                if t is not None:
                    self.feed.log(f"{record['name'] or record['protocol']}: {error}", t,
                                  "warning", f"{record['direction'] or '?'} message")
        elif kind == "event" and self.last_time is not None:
            self.feed.log(_event_text(record), self.last_time, "warning",
                          f"{record.get('direction') or '?'} link")
        elif kind == "frame" and t is not None and record.get("crc_ok"):
            self._frame(record, t)

    def _frame(self, record: dict[str, Any], t: float) -> None:
        direction = record["direction"]
        if record["frame_type"] == "DATA" and record["num"] is not None:
            self.sent[(direction, record["num"])] = t
        elif record["frame_type"] == "ACK" and record["rsp"] is not None:  # RSP: the NUM ACKed
            other = {"h2e": "e2h", "e2h": "h2e"}.get(direction or "")
            sent = self.sent.pop((other, record["rsp"]), None)
            if sent is not None and t >= sent:
                self.feed.ack(t - sent, t)


def _event_text(record: dict[str, Any]) -> str:
    detail = ", ".join(f"{k} {v}" for k, v in record.items()
                       if k not in ("kind", "type", "direction", "index", "time"))
    return f"{record['type']}" + (f" ({detail})" if detail else "")

