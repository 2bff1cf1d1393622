"""The Foxglove topics into the MCAP file of ``export --mcap``, beside its own topics: the
SDK's messages as protobuf with the SDK's schema (a ``FileDescriptorSet``, as Foxglove's own
writer registers it), the plots' numbers as JSON with a JSON Schema."""

from __future__ import annotations

import json
from typing import Any

from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.foxglove.feed import Feed, RecordFeed
from eyeq_spi.foxglove.layout import layout_json
from eyeq_spi.foxglove.topics import FoxgloveMessage
from eyeq_spi.interop.mcap_out import McapWriter
from eyeq_spi.plot.figures import write_file


class McapSink:
    """A :class:`~eyeq_spi.foxglove.topics.Sink` writing to an open :class:`McapWriter`."""

    def __init__(self, writer: McapWriter) -> None:
        self.writer = writer
        self.channels: dict[str, int] = {}

    def message(self, topic: str, msg: FoxgloveMessage, log_time_ns: int) -> None:
        cid = self.channels.get(topic)
        if cid is None:
            schema = msg.get_schema()
            cid = self.channels[topic] = self.writer.register(
                topic, schema_name=schema.name, schema_encoding=schema.encoding,
                schema=bytes(schema.data), message_encoding=schema.encoding)
        self.writer.add(cid, log_time_ns, msg.encode())

    def values(self, topic: str, schema: dict[str, Any], body: dict[str, Any],
               log_time_ns: int) -> None:
        cid = self.channels.get(topic)
        if cid is None:
            cid = self.channels[topic] = self.writer.register(
                topic, schema_name=schema["title"], schema_encoding="jsonschema",
                schema=json.dumps(schema).encode(), message_encoding="json")
        self.writer.add(cid, log_time_ns, json.dumps(body, separators=(",", ":")).encode())


def layout_path(mcap_path: str) -> str:
    """Where ``export --mcap OUT.mcap`` writes the layout: ``OUT.layout.json`` beside it."""
    base = mcap_path[:-5] if mcap_path.lower().endswith(".mcap") else mcap_path
    return f"{base}.layout.json"


class McapScene(RecordFeed):
    """``export --mcap``'s Foxglove topics: every dissector record into the export's MCAP
    writer, and the layout written beside the file (at once: it does not depend on the
    capture)."""

    def __init__(self, writer: McapWriter, codec: MessageCodec, layout: str) -> None:
        write_file(layout, layout_json() + "\n")
        self.layout = layout
        super().__init__(Feed(codec, McapSink(writer)))

    def summary(self) -> dict[str, Any]:
        return {"foxglove": dict(sorted(self.feed.published.items())), "layout": self.layout}

    def written(self) -> list[str]:
        return [f"{self.layout} (Foxglove layout: 3D scene, plots, log; "
                f"{self.feed.scene_updates()} scene updates in the MCAP)"]
