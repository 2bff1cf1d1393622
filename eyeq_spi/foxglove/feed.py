"""Decoded messages and events in, Foxglove topics out (:mod:`eyeq_spi.foxglove.topics`).

:class:`Feed` is the one translation, fed by a capture's dissector records (:class:`RecordFeed`)
or by a running host (:mod:`eyeq_spi.foxglove.live`). Times are seconds on the caller's base; a
sink gets them in ns. A scene message with decode errors is skipped (E2E and counter errors alone
do not hide it, as in every view).
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.foxglove import topics
from eyeq_spi.foxglove.scene import KINDS, SceneMessages, fg, frame_transforms, timestamp
from eyeq_spi.plot.perceived import OBSTACLES, Labels, SceneTracker, walk
from eyeq_spi.plot.vehicle_frame import CAMERA_HEIGHT_M
from eyeq_spi.summary import ack_latency_ms

VEH_STATE = "HOST_VEH_STATE_MSG"
STATS_PERIOD_S = 1.0


def ns(time_s: float) -> int:
    return max(0, round(time_s * 1e9))


def _find(fields: dict[str, Any], key: str) -> float | None:
    """The first number named ``key`` anywhere in decoded fields (every release's layout)."""
    for _, struct in walk(fields):
        value = struct.get(key)
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value)
    return None


def schemas() -> dict[str, Any]:
    """Every topic with its schema: a ``foxglove.messages`` class or a JSON Schema (what a live
    server advertises before the first message)."""
    sdk = fg()
    out: dict[str, Any] = dict.fromkeys(topics.SCENE_TOPICS.values(), sdk.SceneUpdate)
    out.update({topics.TF: sdk.FrameTransform, topics.LOG: sdk.Log, topics.EGO: topics.EGO_SCHEMA,
                topics.STREAMS: topics.STREAMS_SCHEMA, topics.ACK_LATENCY: topics.ACK_SCHEMA})
    return out


class DeadReckoning:
    """The vehicle's pose in ``odom`` from its speed and yaw rate (x, y in m, yaw in rad)."""

    def __init__(self) -> None:
        self.x = self.y = self.yaw = 0.0
        self.last: float | None = None

    def step(self, time_s: float, speed: float, yaw_rate: float) -> None:
        if self.last is not None and 0.0 < time_s - self.last < 1.0:  # a gap or a jump: hold
            dt = time_s - self.last
            self.yaw = math.remainder(self.yaw + yaw_rate * dt, math.tau)
            self.x += speed * math.cos(self.yaw) * dt
            self.y += speed * math.sin(self.yaw) * dt
        self.last = time_s

    def pose(self) -> tuple[float, float, float] | None:
        return None if self.last is None else (self.x, self.y, self.yaw)


class Feed:
    """The Foxglove topics of one run or capture, written to ``sink``."""

    def __init__(self, codec: MessageCodec, sink: topics.Sink, *,
                 camera_height: float = CAMERA_HEIGHT_M) -> None:
        self.sink = sink
        self.tracker = SceneTracker(Labels(codec))
        rates = {msg.name: msg.rate_hz or 0.0 for msg in codec.cat.messages if msg.name in KINDS}
        self.camera_height = camera_height
        self.scenes = SceneMessages(rates, camera_height)
        self.odom = DeadReckoning()
        self.counts: Counter[str] = Counter()  # messages received since the last /streams
        self.acks: Counter[int] = Counter()  # 10 µs bin -> DATA frames ACKed, this second
        self.next_stats: float | None = None
        self.published: Counter[str] = Counter()  # topic -> messages written
        advertise = getattr(sink, "advertise", None)
        if advertise is not None:  # a live client sees every topic as soon as it connects
            advertise(schemas())

    def scene_updates(self) -> int:
        return sum(n for topic, n in self.published.items() if topic.startswith("/scene/"))

    def describe(self) -> str:
        """What was published, one line."""
        return f"{self.scene_updates()} scene updates and {self.published[topics.LOG]} log lines"

    def message(self, name: str | None, fields: dict[str, Any] | None, time_s: float | None,
                errors: list[str] | tuple[str, ...] = ()) -> None:
        """One decoded message, as the host or the dissector delivered it."""
        if time_s is None or name is None:
            return
        if name == VEH_STATE and fields and not errors:
            self._ego(fields, time_s)
        elif name in topics.SCENE_TOPICS and self.tracker.update(name, fields, time_s, errors):
            self._scene(name, time_s)
        self.tick(time_s)

    def _scene(self, name: str, time_s: float) -> None:
        stamp = ns(time_s)
        self._put(topics.SCENE_TOPICS[name],
                  self.scenes.update(name, self.tracker.scene, stamp), stamp)
        if name == OBSTACLES:
            for tf in frame_transforms(stamp, self.odom.pose(), self.camera_height):
                self._put(topics.TF, tf, stamp)

    def _ego(self, fields: dict[str, Any], time_s: float) -> None:
        speed, yaw_rate = _find(fields, "vehicleVelocity"), _find(fields, "vehicleYawRate")
        if speed is None or yaw_rate is None:
            return
        self.ego(speed, yaw_rate, time_s)

    def ego(self, speed: float, yaw_rate: float, time_s: float) -> None:
        """The ego vehicle's speed (m/s) and yaw rate (rad/s, left positive) at ``time_s``."""
        self.odom.step(time_s, speed, yaw_rate)
        self._values(topics.EGO, topics.EGO_SCHEMA, {"speed": speed, "yaw_rate": yaw_rate}, time_s)

    def received(self, name: str, time_s: float) -> None:
        """A message counted for ``/streams`` without its fields (a live host's traffic)."""
        self.counts[name] += 1
        self.tick(time_s)

    def ack(self, latency: float, time_s: float) -> None:
        """One DATA frame's send -> ACK time, seconds."""
        self.ack_bins(Counter({int(latency * 1e5): 1}), time_s)

    def ack_bins(self, bins: Counter[int], time_s: float) -> None:
        """ACK latencies as a link counts them (10 µs bins)."""
        self.acks.update(bins)
        self.tick(time_s)

    def log(self, text: str, time_s: float, level: str = "info", name: str = "eyeq-spi") -> None:
        sdk = fg()
        stamp = ns(time_s)
        self._put(topics.LOG, sdk.Log(timestamp=timestamp(stamp), message=text, name=name,
                                      level=getattr(sdk.LogLevel, level.capitalize())), stamp)

    def tick(self, time_s: float) -> None:
        """Publish the once-a-second topics when their second is over."""
        if self.next_stats is None:
            self.next_stats = time_s + STATS_PERIOD_S
        if time_s < self.next_stats:
            return
        span = STATS_PERIOD_S + max(0.0, time_s - self.next_stats)
        if self.counts:
            self._values(topics.STREAMS, topics.STREAMS_SCHEMA,
                         {k: round(v / span, 2) for k, v in sorted(self.counts.items())}, time_s)
        if self.acks:
            stats = ack_latency_ms(self.acks)
            self._values(topics.ACK_LATENCY, topics.ACK_SCHEMA,
                         {"p50_ms": stats["p50"], "max_ms": stats["max"], "n": stats["n"]}, time_s)
        self.counts.clear()
        self.acks.clear()
        self.next_stats = time_s + STATS_PERIOD_S

    def _put(self, topic: str, msg: Any, stamp: int) -> None:
        self.sink.message(topic, msg, stamp)
        self.published[topic] += 1

    def _values(self, topic: str, schema: dict[str, Any], body: dict[str, Any],
                time_s: float) -> None:
        self.sink.values(topic, schema, body, ns(time_s))
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
        time_s = record.get("time")
        if time_s is not None:
            self.last_time = time_s
        if kind == "message":
            if time_s is not None:
                self.feed.received(record["name"] or record["protocol"], time_s)
            self.feed.message(record["name"], record["fields"], time_s, record["errors"])
            for error in record["errors"]:
                if time_s is not None:
                    self.feed.log(f"{record['name'] or record['protocol']}: {error}", time_s,
                                  "warning", f"{record['direction'] or '?'} message")
        elif kind == "event" and self.last_time is not None:
            self.feed.log(_event_text(record), self.last_time, "warning",
                          f"{record.get('direction') or '?'} link")
        elif kind == "frame" and time_s is not None and record.get("crc_ok"):
            self._frame(record, time_s)

    def describe(self) -> str:
        return self.feed.describe()

    def _frame(self, record: dict[str, Any], time_s: float) -> None:
        direction = record["direction"]
        if record["frame_type"] == "DATA" and record["num"] is not None:
            self.sent[(direction, record["num"])] = time_s
        elif record["frame_type"] == "ACK" and record["rsp"] is not None:  # RSP: the NUM ACKed
            other = {"h2e": "e2h", "e2h": "h2e"}.get(direction or "")
            sent = self.sent.pop((other, record["rsp"]), None)
            if sent is not None and time_s >= sent:
                self.feed.ack(time_s - sent, time_s)


def _event_text(record: dict[str, Any]) -> str:
    detail = ", ".join(f"{k} {v}" for k, v in record.items()
                       if k not in ("kind", "type", "direction", "index", "time"))
    return f"{record['type']}" + (f" ({detail})" if detail else "")

