"""Records of what a sender sent and what its peer's transport delivered, taken by wrapping the
public ``send`` and ``next_event`` of a :class:`TransportConnection` (nothing in the host or the
simulator changes). The oracle: every delivered message is one that was sent, and no sent message
is delivered more often than it was sent."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from eyeq_spi.transport.connection import Event, TransportConnection
from eyeq_spi.transport.events import MessageReceived


@dataclass
class MessageLedger:
    """One direction: the sender's messages and the receiver's deliveries."""

    sent: Counter[bytes] = field(default_factory=Counter)
    delivered: Counter[bytes] = field(default_factory=Counter)
    messages_sent: int = 0
    messages_delivered: int = 0
    corrupted: list[tuple[float, bytes]] = field(default_factory=list)  # never sent as such
    over_delivered: int = 0  # delivered more often than sent
    now: float = 0.0

    def on_sent(self, message: bytes, now: float) -> None:
        self.sent[message] += 1
        self.messages_sent += 1
        self.now = now

    def on_delivered(self, message: bytes) -> None:
        self.messages_delivered += 1
        self.delivered[message] += 1
        if message not in self.sent:
            # every one counted, the first 100 kept
            self.corrupted.append((self.now, message if len(self.corrupted) < 100 else b""))
        elif self.delivered[message] > self.sent[message]:
            self.over_delivered += 1

    @property
    def bad_deliveries(self) -> int:
        return len(self.corrupted) + self.over_delivered


def tap(sender: TransportConnection, receiver: TransportConnection,
        ledger: MessageLedger | None = None) -> MessageLedger:
    """Wrap ``sender.send`` and ``receiver.next_event`` so that ``ledger`` sees both ends."""
    book = ledger or MessageLedger()
    send: Callable[[bytes, float], int] = sender.send
    next_event: Callable[[], Event | None] = receiver.next_event

    def send_tapped(message: bytes, now: float) -> int:
        book.on_sent(bytes(message), now)
        return send(message, now)

    def next_event_tapped() -> Event | None:
        ev = next_event()
        if isinstance(ev, MessageReceived):
            book.on_delivered(ev.data)
        return ev

    setattr(sender, "send", send_tapped)  # noqa: B010 - an instance wrapper, not a patch
    setattr(receiver, "next_event", next_event_tapped)  # noqa: B010
    return book
