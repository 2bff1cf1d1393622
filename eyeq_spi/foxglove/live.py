"""A live run on a Foxglove sink (``--foxglove`` of ``demo``, ``host``, ``replay``, ``monitor``).

The link path pays one dict store per scene message and one counter per message: the latest
message of each scene kind is published at most once per DASP period (1/18 s), one kind per
call, so no single call pays for the whole scene (``tools/bench_foxglove.py``); a sink nobody is
subscribed to gets no scene built.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from eyeq_spi.codec.message import DecodedMessage
from eyeq_spi.foxglove.feed import Feed
from eyeq_spi.foxglove.topics import SCENE_TOPICS, Sink

DASP_PERIOD_S = 1.0 / 18.0  # the scene streams' nominal rate (seed 004's message table)
BAD_STATES = ("FAILED", "BOOT_FAILED", "FATAL")


class MessageFeed:
    """Decoded messages of a live run (:meth:`message`) published to ``sink`` at most once per
    ``period`` of their own clock: the latest message of each scene kind, every message
    counted for ``/streams``."""

    def __init__(self, codec: Any, sink: Sink, *, period: float = DASP_PERIOD_S) -> None:
        self.sink = sink
        self.feed = Feed(codec, sink)
        self.period = period
        self.latest: dict[str, DecodedMessage] = {}
        self.due: float | None = None
        self.scene_due: dict[str, float] = {}  # scene kind -> when it may go out again
        self.publishes = 0

    def message(self, out: DecodedMessage, now: float) -> None:
        """One message received (or played) at ``now``."""
        if out.name in SCENE_TOPICS:
            self.latest[out.name] = out
        self.traffic(out.name or out.protocol, now)

    def traffic(self, name: str, now: float) -> None:
        """A message counted at ``now``; what is due is published: the once-a-period topics,
        or one scene kind (never more in one call, so no call costs the loop a whole scene)."""
        self.feed.received(name, now)
        if self.due is None or now >= self.due:
            self.due = now + self.period
            self.publish(now)
        elif self.latest:
            self.scene(now)

    def publish(self, now: float) -> None:
        """The once-a-period topics at ``now``, and one scene kind if one is due."""
        self.publishes += 1
        self.scene(now)

    def scene(self, now: float) -> None:
        """The oldest due scene message's SceneUpdate (at most one per kind and period), built
        only when a client looks."""
        due = [name for name in self.latest if self.scene_due.get(name, now) <= now]
        if not due:
            return
        name = min(due, key=lambda kind: self.scene_due.get(kind, now))
        out = self.latest.pop(name)
        self.scene_due[name] = now + self.period
        subscribed = getattr(self.sink, "subscribed", None)
        if subscribed is None or subscribed():
            self.feed.message(name, out.fields, now, out.errors)

    def describe(self) -> str:
        """What was published, one line."""
        return f"{self.feed.describe()} in {self.publishes} publishes"


def link_counts(host: Any, aborted: str) -> dict[str, int]:
    """``host``'s link counters by seed name, and its transfer aborts as ``aborted: reason``."""
    link: dict[str, int] = dict(host.conn.link.counters.seed_view())
    for reason, count in dict(host.conn.counters.transferAborts).items():
        link[f"{aborted}: {reason}"] = int(count)
    return link


class HostFeed(MessageFeed):
    """Publishes ``host``'s scene, transitions, link events and figures to ``sink``."""

    def __init__(self, host: Any, sink: Sink, *, period: float = DASP_PERIOD_S) -> None:
        super().__init__(host.codec, sink, period=period)
        self.host = host
        self.shown = len(host.transitions)
        self.link_seen = link_counts(host, "transfer aborted")
        self.acks_seen: Counter[int] = Counter(host.conn.link.ack_latency)
        host.subscribe(self._on_message)
        host.subscribe_traffic(self.traffic)

    def _on_message(self, out: DecodedMessage) -> None:
        if out.name in SCENE_TOPICS:  # counted by the traffic callback, published there
            self.latest[out.name] = out

    def publish(self, now: float) -> None:
        self._transitions()
        self._link(now)
        super().publish(now)
        scenario = getattr(self.host, "scenario", None)
        if scenario is not None:
            signals = scenario.signals(now)
            speed, yaw_rate = signals.get("vehicleVelocity"), signals.get("vehicleYawRate")
            if speed is not None and yaw_rate is not None:
                self.feed.ego(float(speed), float(yaw_rate), now)
        hist = Counter(self.host.conn.link.ack_latency)
        fresh = hist - self.acks_seen
        self.acks_seen = hist
        self.feed.ack_bins(fresh, now)

    def _transitions(self) -> None:
        for tr in self.host.transitions[self.shown:]:
            detail = f"  {tr.detail}" if getattr(tr, "detail", "") else ""
            level = "error" if tr.dst.value in BAD_STATES else "info"
            self.feed.log(f"{tr.src.value} --{tr.event.value}--> {tr.dst.value}{detail}",
                          tr.time, level, "host")
        self.shown = len(self.host.transitions)

    def _link(self, now: float) -> None:
        counts = link_counts(self.host, "transfer aborted")
        for name, count in counts.items():
            before = self.link_seen.get(name, 0)
            if count > before:
                self.feed.log(f"{name} +{count - before} (total {count})", now, "warning",
                              "link")
        self.link_seen = counts

