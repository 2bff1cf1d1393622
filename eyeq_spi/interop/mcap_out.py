"""Capture -> MCAP (the mcap library, zstd chunks), for Foxglove.

Topics, all JSON with a JSON Schema (Foxglove's ``jsonschema`` encoding):
- ``/spi/<direction>/transfers``: every transfer, raw bytes base64 (``contentEncoding``) with
  the dissector's frame record (kind, NUM, RSP, CRC, transport);
- ``/eyeq/<direction>/<MESSAGE_NAME>``: each decoded message (header, fields, errors) with a
  schema built from its first instance;
- ``/spi/events``: link and transport events (aborts, duplicates, resynchronisation...).
Log times are the capture's, in nanoseconds (the frame index in µs for inputs without times).
A metadata record ``eyeq-spi`` carries the SW release used to decode, the capture source and
the tool version.
"""

from __future__ import annotations

import base64
import json
from typing import IO, Any

from eyeq_spi import __version__
from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.errors import OutputError
from eyeq_spi.interop.mdf import need

_TRANSFER_SCHEMA: dict[str, Any] = {
    "type": "object", "title": "eyeq_spi.Transfer",
    "properties": {
        "index": {"type": "integer"}, "time": {"type": ["number", "null"]},
        "direction": {"type": ["string", "null"]},
        "data": {"type": "string", "contentEncoding": "base64",
                 "description": "the SPI transfer as on the wire (normally 128 bytes, L1)"},
        "length": {"type": "integer"}, "frame_type": {"type": "string"},
        "num": {"type": ["integer", "null"]}, "rsp": {"type": ["integer", "null"]},
        "crc_ok": {"type": "boolean"}, "transport": {"type": ["string", "null"]},
        "transfer_id": {"type": ["integer", "null"]}, "nak_reason": {"type": ["integer", "null"]},
    },
}
_EVENT_SCHEMA: dict[str, Any] = {"type": "object", "title": "eyeq_spi.Event",
                                 "properties": {"type": {"type": "string"},
                                                "direction": {"type": ["string", "null"]},
                                                "index": {"type": "integer"}}}


_JSON_TYPES = ((bool, "boolean"), (int, "integer"), (float, "number"), (str, "string"))


def json_schema(value: Any) -> dict[str, Any]:
    if isinstance(value, dict):
        return {"type": "object", "properties": {k: json_schema(v) for k, v in value.items()}}
    if isinstance(value, list):
        return {"type": "array", "items": json_schema(value[0]) if value else {}}
    for kind, name in _JSON_TYPES:  # bool before int: a bool is an int
        if isinstance(value, kind):
            return {"type": name}
    return {}


class McapWriter:
    def __init__(self, fh: IO[bytes], *, sw: str, source: str) -> None:
        writer_mod = need("mcap.writer", "--mcap")
        need("zstandard", "--mcap")
        self.mcap = writer_mod.Writer(fh, compression=writer_mod.CompressionType.ZSTD)
        self.mcap.start(profile="", library=f"eyeq-spi {__version__}")
        self.meta = {"sw_release": sw, "capture_source": source,
                     "eyeq_spi_version": __version__}
        self.channels: dict[str, int] = {}
        self.seq = 0
        self.messages = 0
        self.last_time: float | None = None

    def _channel(self, topic: str, schema: dict[str, Any], title: str) -> int:
        cid = self.channels.get(topic)
        if cid is None:
            cid = self.register(topic, schema_name=title, schema_encoding="jsonschema",
                                schema=json.dumps({**schema, "title": title}).encode(),
                                message_encoding="json")
        return cid

    def register(self, topic: str, *, schema_name: str, schema_encoding: str, schema: bytes,
                 message_encoding: str) -> int:
        """The channel of ``topic`` (registered with its schema on first use): for topics in
        other encodings than this module's JSON (Foxglove's protobuf schemas)."""
        cid = self.channels.get(topic)
        if cid is None:
            sid = self.mcap.register_schema(name=schema_name, encoding=schema_encoding, data=schema)
            cid = self.mcap.register_channel(topic=topic, message_encoding=message_encoding,
                                          schema_id=sid)
            self.channels[topic] = cid
        return int(cid)

    def add(self, cid: int, log_time_ns: int, data: bytes) -> None:
        """One message, already encoded, on a channel of :meth:`register`."""
        self.seq += 1
        self.mcap.add_message(channel_id=cid, log_time=max(0, log_time_ns),
                           publish_time=max(0, log_time_ns), sequence=self.seq, data=data)

    def _put(self, cid: int, time: float | None, index: int, body: dict[str, Any]) -> None:
        ns = round(time * 1e9) if time is not None else index * 1000
        self.add(cid, ns, json.dumps(body, separators=(",", ":")).encode())

    def transfer(self, transfer: Transfer, frame: dict[str, Any]) -> None:
        topic = f"/spi/{transfer.direction or 'unknown'}/transfers"
        cid = self._channel(topic, _TRANSFER_SCHEMA, "eyeq_spi.Transfer")
        body = {k: frame[k] for k in ("index", "time", "direction", "frame_type", "num", "rsp",
                                      "crc_ok", "transport", "transfer_id", "nak_reason")}
        body["length"] = len(transfer.data)
        body["data"] = base64.b64encode(transfer.data).decode("ascii")
        self._put(cid, transfer.time, frame["index"], body)
        self.last_time = transfer.time if transfer.time is not None else self.last_time

    def write(self, record: dict[str, Any]) -> None:
        """One of the dissector's message or event records."""
        if record["kind"] == "message":
            name = record["name"] or record["protocol"]
            body = {key: record[key] for key in ("time", "direction", "protocol", "name",
                                                  "length", "frames", "header", "fields",
                                                  "errors")}
            topic = f"/eyeq/{record['direction'] or 'unknown'}/{name}"
            cid = self._channel(topic, json_schema(body), f"eyeq_spi.{name}")
            last = next((f for f in reversed(record["frames"]) if f is not None), 0)
            self._put(cid, record["time"], last, body)
            self.messages += 1
        elif record["kind"] == "event":
            cid = self._channel("/spi/events", _EVENT_SCHEMA, "eyeq_spi.Event")
            self._put(cid, self.last_time, record["index"], record)

    def close(self) -> None:
        try:
            self.mcap.add_metadata(name="eyeq-spi", data={k: str(v) for k, v in self.meta.items()})
            self.mcap.finish()
        except OSError as exc:
            raise OutputError(f"cannot write the MCAP file: {exc}") from None
