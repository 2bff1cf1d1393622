"""The interface every sans-IO stack exposes to a runner (docs/STYLE.md §2)."""

from __future__ import annotations

from typing import Protocol


class Node(Protocol):
    """A node may also declare ``SELF_CONTAINED = True`` (an attribute of its own class, not
    inherited; read once by :class:`~eyeq_spi.runner.virtual.VirtualRunner`): its calls act on
    nothing but itself, and once ``data_to_send`` has been called after a ``receive_data`` or
    ``handle_timer``, a call that hands over nothing leaves ``get_timer()`` unchanged; one
    ``data_to_send(now)`` call hands over everything due at ``now``. The runner then re-asks only
    this node after touching it; without it, every node.

    Every node: ``data_to_send(now)`` hands over nothing unless the node was touched since its
    last call or ``get_timer()`` is at most ``now`` (the runner does not ask it otherwise).
    ``VirtualRunner.verify`` checks both promises.

    Optional, read from the node's own class only (runner/virtual_fast.py):
    ``express_absorb(transfer, now) -> list[bytes] | None`` makes the calls a runner makes for
    one arriving transfer (``receive_data``; ``handle_timer`` if that made the timer due;
    ``data_to_send``) in one step and returns what ``data_to_send`` hands over, or returns None
    having changed nothing when it cannot tell that they would do nothing else. It is called
    only while the node's ``get_timer()`` is later than ``now``.

    Optional as well, for the handover of a message's rest (runner/virtual_fast.py): on a
    sending node ``express_run(now) -> DataRun | None`` (the rest of the message it is sending,
    from :meth:`~eyeq_spi.link.connection.LinkConnection.data_run`, due no later than its own
    next deadline) and ``express_run_take(run, released, acked)`` (the releases and ACKs the
    runner computed, as the per-frame calls at those times would do them); on a receiving node
    ``express_take(frames, times, acks) -> int`` (``express_absorb`` of each frame at its time,
    frame after frame, up to the first it would decline or whose ACK would differ)."""

    def receive_data(self, transfer: bytes, now: float) -> None: ...

    def data_to_send(self, now: float) -> list[bytes]: ...

    def get_timer(self) -> float | None: ...

    def handle_timer(self, now: float) -> None: ...
