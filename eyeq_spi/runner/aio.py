"""The asyncio adapter of a sans-IO node's deliveries: an async iterator over the messages a
node hands to its subscribers. The node itself never touches asyncio; this module is the glue
(docs/STYLE.md, aioquic: only the asyncio glue knows about the event loop)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from typing import TypeVar

T = TypeVar("T")

Subscribe = Callable[[Callable[[T], None]], None]
"""A node's ``subscribe(callback)``: the callback gets every message the node delivers."""


def message_stream(subscribe: Subscribe[T]) -> AsyncIterator[T]:
    """An async iterator over every message delivered from now on, e.g.
    ``message_stream(host.subscribe)``, with its own unbounded queue filled by the node's calls."""
    queue: asyncio.Queue[T] = asyncio.Queue()
    subscribe(queue.put_nowait)

    async def stream() -> AsyncIterator[T]:
        while True:
            yield await queue.get()

    return stream()
