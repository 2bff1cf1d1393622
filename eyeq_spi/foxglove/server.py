"""A live Foxglove WebSocket server (the SDK's) as a :class:`~eyeq_spi.foxglove.topics.Sink`
(``--foxglove [HOST:PORT]``). The server runs on the SDK's threads and queues per client, so the
run's loop never waits on a client; log times are the wall clock's, as Foxglove shows a live
source.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from typing import Any, cast

from eyeq_spi.errors import AdapterError, MissingExtra, UsageError
from eyeq_spi.foxglove.topics import FoxgloveMessage

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765  # Foxglove's default for a WebSocket connection
BACKLOG = 256  # messages queued per client before the oldest is dropped


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT``, ``:PORT`` or ``HOST`` (port 8765); port 0 picks a free one."""
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = text, str(DEFAULT_PORT)
    host = (host or DEFAULT_HOST).strip("[]")
    try:
        number = int(port)
    except ValueError:
        raise UsageError(f"{text}: give HOST:PORT, the port a number") from None
    if not 0 <= number <= 65535:
        raise UsageError(f"{text}: the port must be 0..65535")
    return host, number


class _Subscriptions:
    """The SDK's server listener: how many client subscriptions are open."""

    def __init__(self) -> None:
        self.count = 0
        self.lock = threading.Lock()

    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self.lock:
            self.count += 1

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self.lock:
            self.count = max(0, self.count - 1)


class ServerSink:
    """A started Foxglove WebSocket server on ``address`` (``HOST:PORT``)."""

    def __init__(self, address: str, *, name: str = "eyeq-spi",
                 wall: Callable[[], float] = time.time) -> None:
        try:
            import foxglove
        except ImportError:
            raise MissingExtra("foxglove", "--foxglove") from None
        host, port = parse_address(address)
        self.fg = foxglove
        self.context = foxglove.Context()
        self.listener = _Subscriptions()
        try:
            self.server = foxglove.start_server(
                name=name, host=host, port=port, context=self.context,
                # the SDK calls the listener's methods it has (two of its protocol's)
                server_listener=cast(Any, self.listener), message_backlog_size=BACKLOG)
        except Exception as exc:  # the SDK raises its own error for a port in use
            raise AdapterError(f"--foxglove {address}: cannot serve there ({exc})") from None
        self.host = host
        self.port = int(self.server.port)
        self.channels: dict[str, Any] = {}
        self.wall = wall
        self.offset_ns: int | None = None

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def subscribed(self) -> bool:
        """True while a client is subscribed to any topic (nothing is built for nobody)."""
        return self.listener.count > 0

    def _time(self, log_time_ns: int) -> int:
        if self.offset_ns is None:
            self.offset_ns = round(self.wall() * 1e9) - log_time_ns
        return log_time_ns + self.offset_ns

    def _channel(self, topic: str, schema: FoxgloveMessage | dict[str, Any]) -> Any:
        """The channel of ``topic``, opened on first use for a message class or a JSON Schema."""
        if topic in self.channels:
            return self.channels[topic]
        if isinstance(schema, dict):
            channel = self.fg.Channel(topic, schema=schema, context=self.context)
        else:
            sdk_schema = schema.get_schema()
            channel = self.fg.Channel(topic, schema=sdk_schema,
                                      message_encoding=sdk_schema.encoding, context=self.context)
        self.channels[topic] = channel
        return channel

    def message(self, topic: str, msg: FoxgloveMessage, log_time_ns: int) -> None:
        self._channel(topic, msg).log(msg.encode(), log_time=self._time(log_time_ns))

    def values(self, topic: str, schema: dict[str, Any], body: dict[str, Any],
               log_time_ns: int) -> None:
        self._channel(topic, schema).log(json.dumps(body).encode(),
                                         log_time=self._time(log_time_ns))

    def advertise(self, topics: dict[str, FoxgloveMessage | dict[str, Any]]) -> None:
        """Open the channels of ``topics`` (topic -> a message class or a JSON Schema) before
        the first message, so a client sees every topic as soon as it connects."""
        for topic, schema in topics.items():
            self._channel(topic, schema)

    def close(self) -> None:
        self.server.stop()
