"""The asyncio adapter (runner/aio.py): an async iterator over what a sans-IO node delivers to its
subscribers; ``HostEmulator.messages()`` is built on it."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from eyeq_spi.runner.aio import message_stream


def test_message_stream_yields_what_the_node_delivers_in_order() -> None:
    callbacks: list[Callable[[int], None]] = []
    stream = message_stream(callbacks.append)
    assert len(callbacks) == 1
    for i in range(3):
        callbacks[0](i)

    async def take() -> list[int]:
        return [await stream.__anext__() for _ in range(3)]

    assert asyncio.run(take()) == [0, 1, 2]
