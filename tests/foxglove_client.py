"""A small Foxglove WebSocket client for the live tests: read the server's channel
advertisements, subscribe, and decode each message's protobuf payload with the schema the
server advertised (the SDK's).

It offers both names of the protocol, as the Foxglove app does: ``foxglove.sdk.v1``, which the
SDK's server (0.30) requires, and ``foxglove.websocket.v1``, the same protocol under its older
name."""

from __future__ import annotations

import base64
import contextlib
import json
import struct
import time
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
MESSAGE_DATA = 0x01  # binary opcode: subscription id u32, log time u64, payload (LE)


def message_class(schema_name: str, descriptor_set: bytes) -> Any:
    """The protobuf message class of ``schema_name`` from a serialized FileDescriptorSet."""
    files = descriptor_pb2.FileDescriptorSet.FromString(descriptor_set)
    pool = descriptor_pool.DescriptorPool()
    pending = list(files.file)
    while pending:  # dependencies first, whatever order the set lists them in
        added = [fd for fd in pending if all(pool_has(pool, dep) for dep in fd.dependency)]
        if not added:
            raise AssertionError(f"unresolved imports in {[fd.name for fd in pending]}")
        for fd in added:
            pool.Add(fd)
            pending.remove(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def pool_has(pool: Any, name: str) -> bool:
    try:
        pool.FindFileByName(name)
    except KeyError:
        return False
    return True


class Client:
    def __init__(self, url: str, timeout: float = 20.0) -> None:
        from websockets.sync.client import connect
        from websockets.typing import Subprotocol

        self.stack = contextlib.ExitStack()
        offered = [Subprotocol(name) for name in SUBPROTOCOLS]
        self.ws = self.stack.enter_context(connect(
            url, subprotocols=offered, open_timeout=timeout, max_size=None,
            proxy=None, compression=None))  # loopback, never through a proxy
        self.channels: dict[str, dict[str, Any]] = {}  # topic -> advertised channel
        self.subscriptions: dict[int, dict[str, Any]] = {}

    def close(self) -> None:
        self.stack.close()

    def wait_for(self, topics: list[str], timeout: float = 20.0) -> None:
        """Read control messages until every topic in ``topics`` is advertised."""
        end = time.monotonic() + timeout
        while not all(t in self.channels for t in topics):
            left = end - time.monotonic()
            if left <= 0:
                raise AssertionError(f"not advertised: {topics}; got {sorted(self.channels)}")
            self._handle(self.ws.recv(timeout=left))

    def _handle(self, frame: str | bytes) -> tuple[dict[str, Any], int, bytes] | None:
        if isinstance(frame, str):
            msg = json.loads(frame)
            if msg.get("op") == "advertise":
                for ch in msg["channels"]:
                    self.channels[ch["topic"]] = ch
            return None
        if frame[0] != MESSAGE_DATA:
            return None
        sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
        return self.subscriptions[sub_id], log_time, bytes(frame[13:])

    def subscribe(self, topic: str, sub_id: int) -> None:
        channel = self.channels[topic]
        self.subscriptions[sub_id] = channel
        self.ws.send(json.dumps({"op": "subscribe",
                                 "subscriptions": [{"id": sub_id, "channelId": channel["id"]}]}))

    def decoder(self, topic: str) -> Any:
        channel = self.channels[topic]
        assert channel["encoding"] == "protobuf", channel
        return message_class(channel["schemaName"], base64.b64decode(channel["schema"]))

    def receive(self, seconds: float) -> list[tuple[str, float, int, bytes]]:
        """Every message that arrives within ``seconds``: (topic, arrival on the monotonic
        clock, log time ns, payload)."""
        out = []
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            try:
                frame = self.ws.recv(timeout=left)
            except TimeoutError:
                break
            got = self._handle(frame)
            if got is not None:
                channel, log_time, payload = got
                out.append((channel["topic"], time.monotonic(), log_time, payload))
        return out
