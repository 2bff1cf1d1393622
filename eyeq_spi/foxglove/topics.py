"""The Foxglove topics (listed with their schemas in docs/foxglove.md), and the one interface
their outputs implement."""

from __future__ import annotations

from typing import Any, Protocol

SCENE_TOPICS = {
    "EYEQ_VIS_OBSTACLES_MSG": "/scene/obstacles",
    "EYEQ_VIS_ROAD_DATA_MSG": "/scene/lanes",
    "EYEQ_VIS_TRAFFIC_SIGNS_MSG": "/scene/signs",
    "EYEQ_VIS_LIGHT_SENSOR_DATA_MSG": "/scene/lights",
}
TF = "/tf"
LOG = "/log"
EGO = "/ego"
STREAMS = "/streams"
ACK_LATENCY = "/link/ack_latency"
WORLD_FRAME = "odom"  # where the vehicle moves, dead-reckoned from its speed and yaw rate

EGO_SCHEMA: dict[str, Any] = {
    "type": "object", "title": "eyeq_spi.Ego",
    "properties": {"speed": {"type": "number", "description": "m/s"},
                   "yaw_rate": {"type": "number", "description": "rad/s, left positive"}}}
STREAMS_SCHEMA: dict[str, Any] = {
    "type": "object", "title": "eyeq_spi.StreamRates",
    "description": "received messages per second over the last second, by message name",
    "additionalProperties": {"type": "number"}}
ACK_SCHEMA: dict[str, Any] = {
    "type": "object", "title": "eyeq_spi.AckLatency",
    "properties": {"p50_ms": {"type": "number"}, "max_ms": {"type": "number"},
                   "n": {"type": "integer"}}}


class FoxgloveMessage(Protocol):
    """A message class of ``foxglove.messages`` (SceneUpdate, FrameTransform, Log...)."""

    def encode(self) -> bytes: ...

    @classmethod
    def get_schema(cls) -> Any: ...


class Sink(Protocol):
    """Where the feed's messages go: an MCAP file or a live WebSocket server. Times are
    nanoseconds on the sink's time base (a capture's times, or the run's clock)."""

    def message(self, topic: str, msg: FoxgloveMessage, log_time_ns: int) -> None:
        """One message in a Foxglove schema (protobuf, the schema from the SDK)."""

    def values(self, topic: str, schema: dict[str, Any], body: dict[str, Any],
               log_time_ns: int) -> None:
        """One JSON message (a plot's numbers) with its JSON Schema."""
