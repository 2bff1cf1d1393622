"""The interface every sans-IO stack exposes to a runner (STYLE.md §2)."""

from __future__ import annotations

from typing import Protocol


class Node(Protocol):
    def receive_data(self, transfer: bytes, now: float) -> None: ...

    def data_to_send(self, now: float) -> list[bytes]: ...

    def get_timer(self) -> float | None: ...

    def handle_timer(self, now: float) -> None: ...
