"""A running host's view on a Foxglove sink (``demo``, ``host``, ``replay``, ``monitor`` with
``--foxglove``), through the host's public face only: ``subscribe`` (decoded DASP messages),
``subscribe_traffic`` (every message received or sent, with its time), ``transitions``, its
counters and its link's ACK latency histogram.

The link path pays one dict store per scene message and one counter per message: the host's
subscriber keeps the latest message of each scene kind, and the traffic callback publishes
what is new at most once per DASP period (1/18 s), so the scene goes out at the DASP rate
whatever the link does. A sink that says nobody is subscribed (:meth:`ServerSink.subscribed`)
gets no scene built at all.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from eyeq_spi.codec.message import DecodedMessage
from eyeq_spi.foxglove.feed import Feed, schemas
from eyeq_spi.foxglove.topics import SCENE_TOPICS, Sink

DASP_PERIOD_S = 1.0 / 18.0  # the scene streams' nominal rate (seed 004's message table)
BAD_STATES = ("FAILED", "BOOT_FAILED", "FATAL")


class HostFeed:
    """Publishes ``host``'s scene, transitions, link events and figures to ``sink``."""

    def __init__(self, host: Any, sink: Sink, *, period: float = DASP_PERIOD_S) -> None:
        self.host = host
        self.sink = sink
        self.feed = Feed(host.codec, sink)
        self.period = period
        self.latest: dict[str, DecodedMessage] = {}
        self.due: float | None = None
        self.shown = len(host.transitions)
        self.link_seen = self._link_counts()
        self.acks_seen: Counter[int] = Counter(host.conn.link.ack_latency)
        self.publishes = 0
        advertise = getattr(sink, "advertise", None)
        if advertise is not None:  # a client sees every topic as soon as it connects
            advertise(schemas())
        host.subscribe(self._on_message)
        host.subscribe_traffic(self._on_traffic)

    def _on_message(self, out: DecodedMessage) -> None:
        if out.name in SCENE_TOPICS:
            self.latest[out.name] = out

    def _on_traffic(self, name: str, now: float) -> None:
        self.feed.received(name, now)
        if self.due is None or now >= self.due:
            self.due = now + self.period
            self.publish(now)

    def publish(self, now: float) -> None:
        """What changed since the last publish, at ``now`` (the host's clock)."""
        self.publishes += 1
        self._transitions()
        self._link(now)
        subscribed = getattr(self.sink, "subscribed", None)
        if subscribed is not None and not subscribed():
            self.latest.clear()  # nobody looks: build nothing
            return
        for name, out in self.latest.items():
            self.feed.message(name, out.fields, now, out.errors)
        self.latest.clear()
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

    def _link_counts(self) -> dict[str, int]:
        link = self.host.conn.link.counters.seed_view()
        for reason, count in dict(self.host.conn.counters.transferAborts).items():
            link[f"transfer aborted: {reason}"] = int(count)
        return link

    def _link(self, now: float) -> None:
        counts = self._link_counts()
        for name, count in counts.items():
            before = self.link_seen.get(name, 0)
            if count > before:
                self.feed.log(f"{name} +{count - before} (total {count})", now, "warning",
                              "link")
        self.link_seen = counts

    def describe(self) -> str:
        """What was published, one line."""
        scenes = sum(n for topic, n in self.feed.published.items() if topic.startswith("/scene/"))
        return (f"{scenes} scene updates and {self.feed.published['/log']} log lines in "
                f"{self.publishes} publishes")
