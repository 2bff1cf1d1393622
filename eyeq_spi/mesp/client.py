"""Sans-IO MESP client (decisions M1, M6).

Tags: bits 0..5 count +1 per request (retries included) and wrap at 63; bit 7 marks a reply.
Several requests may be in flight; a reply is matched exactly on (service, function, counter).
A reply that matches nothing outstanding — late, duplicated or bogus — is dropped and counted
(``stale_replies``): a late reply to an attempt that already timed out can never complete the
retry, which is the stale-reply bug this avoids. Each attempt has a deadline (500 ms); a timed-out
request is retried under a new tag up to ``max_attempts`` in all, then fails.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from eyeq_spi.catalog.messages import Catalog, catalog
from eyeq_spi.codec.mesp import REPLY_BIT, TAG_MASK, MespCodec
from eyeq_spi.codec.message import is_mesp
from eyeq_spi.errors import LocalProtocolError
from eyeq_spi.mesp.replies import MespFailure, MespReply, MespResult, typed

_M = catalog().raw["mesp.yaml"]["mesp"]


@dataclass(frozen=True)
class MespCompleted:
    request_id: int
    reply: MespReply


@dataclass(frozen=True)
class MespFailed:
    request_id: int
    failure: MespFailure  # a plain value, not an exception


@dataclass(frozen=True)
class StaleReply:
    service: int
    function: int
    tag: int


MespEvent = MespCompleted | MespFailed | StaleReply
Callback = Callable[[MespResult], None]


@dataclass
class _Pending:
    request_id: int
    function: str
    params: dict[str, Any]
    counter: int
    key: tuple[int, int, int]
    first_sent: float
    deadline: float
    attempts: int
    callback: Callback | None


@dataclass
class MespClientCounters:
    requests: int = 0
    retries: int = 0
    timeouts: int = 0
    failures: int = 0
    stale_replies: int = 0
    abandoned: int = 0  # outstanding when the EyeQ reset: no reply will come


class MespClient:
    def __init__(
        self,
        cat: Catalog | None = None,
        *,
        deadline: float = float(_M["reply_deadline"]),
        max_attempts: int = int(_M["max_attempts"]),
    ) -> None:
        if deadline <= 0 or max_attempts < 1:
            raise LocalProtocolError("deadline must be > 0 and max_attempts >= 1")
        self.codec = MespCodec(cat or catalog())
        self.deadline = deadline
        self.max_attempts = max_attempts
        self.counters = MespClientCounters()
        self._counter = 0
        self._next_id = 0
        self._pending: dict[tuple[int, int, int], _Pending] = {}
        self._out: deque[bytes] = deque()
        self._events: deque[MespEvent] = deque()

    def request(
        self, function: str, params: dict[str, Any] | None = None, *, now: float,
        callback: Callback | None = None,
    ) -> int:
        """Queue a request; returns its id (carried by the completion event)."""
        definition = self.codec.function(function)
        rid = self._next_id
        self._next_id += 1
        self.counters.requests += 1
        pending = _Pending(rid, definition.name, dict(params or {}), 0, (0, 0, 0), now, now, 0,
                           callback)
        self._send(pending, now)
        return rid

    @property
    def outstanding(self) -> int:
        return len(self._pending)

    def cancel_all(self) -> None:
        """Forget every outstanding request (the EyeQ reset, so none will be answered): counted
        ``abandoned``, not timed out nor retried; late replies count as stale."""
        self.counters.abandoned += len(self._pending)
        self._pending.clear()

    @property
    def waiting(self) -> int:
        """Requests built but not yet handed over by :meth:`data_to_send`."""
        return len(self._out)

    def data_to_send(self) -> list[bytes]:
        out = list(self._out)
        self._out.clear()
        return out

    def next_event(self) -> MespEvent | None:
        return self._events.popleft() if self._events else None

    # -- timers -----------------------------------------------------------------------------
    def get_timer(self) -> float | None:
        return min((p.deadline for p in self._pending.values()), default=None)

    def handle_timer(self, now: float) -> None:
        for key in [k for k, pending in self._pending.items() if pending.deadline <= now]:
            pending = self._pending.pop(key)
            self.counters.timeouts += 1
            if pending.attempts < self.max_attempts:
                self.counters.retries += 1
                self._send(pending, now)
            else:
                self._finish(pending, MespFailure(pending.function, None, "no reply (timeout)",
                                                  pending.attempts))

    # -- receive ----------------------------------------------------------------------------
    def receive_message(self, data: bytes, now: float) -> bool:
        """Feed a reassembled MESP message. Returns False if it is not a MESP reply."""
        if not is_mesp(data) or not data[4] & REPLY_BIT:
            return False
        key = (data[0], data[3], data[4] & TAG_MASK)
        pending = self._pending.pop(key, None)
        if pending is None:
            self.counters.stale_replies += 1
            self._events.append(StaleReply(data[0], data[3], data[4]))
            return True
        decoded = self.codec.decode(data)
        ret = decoded.fields.get("ret")
        if decoded.errors or ret is None:
            err = "; ".join(decoded.errors) or "reply without ret"
            self._finish(pending, MespFailure(pending.function, ret, f"malformed reply: {err}",
                                              pending.attempts))
        elif ret != 0:
            name = self.codec.ret_names.get(ret, "unknown ret")
            self._finish(pending, MespFailure(pending.function, ret, name, pending.attempts))
        else:
            values = {k: v for k, v in decoded.fields.items() if k != "ret"}
            latency = now - pending.first_sent
            self._finish(pending, MespReply(pending.function, data[4],
                                            typed(self.codec.function(pending.function), values),
                                            pending.attempts, latency))
        return True

    def _next_counter(self, service: int, function: int) -> int:
        for _ in range(TAG_MASK + 1):
            counter = self._counter
            self._counter = (counter + 1) & TAG_MASK
            if (service, function, counter) not in self._pending:
                return counter
        raise LocalProtocolError("64 requests of one function outstanding: no free tag")

    def _send(self, pending: _Pending, now: float) -> None:
        definition = self.codec.function(pending.function)
        pending.counter = self._next_counter(definition.service, definition.function)
        pending.key = (definition.service, definition.function, pending.counter)
        pending.attempts += 1
        pending.deadline = now + self.deadline
        self._pending[pending.key] = pending
        self._out.append(self.codec.encode_request(pending.function, pending.counter,
                                                   pending.params))

    def _finish(self, pending: _Pending, result: MespResult) -> None:
        if isinstance(result, MespFailure):
            self.counters.failures += 1
            self._events.append(MespFailed(pending.request_id, result))
        else:
            self._events.append(MespCompleted(pending.request_id, result))
        if pending.callback is not None:
            pending.callback(result)
