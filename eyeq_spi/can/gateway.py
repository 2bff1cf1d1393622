"""The live CAN gateway: decoded EyeQ4 DASP messages in, Mobileye CAN frames out (C3, C4).

:class:`CanGateway` is sans-IO: ``on_message`` keeps the newest fields of every DASP message;
each CAN message is due every ``cycle_ms`` (C3) from the first DASP message on, on the injected
clock; ``handle_timer(now)`` evaluates ``specs/can/mapping.yaml`` (C4), turns physical values into
raw ones (out of range: clamp or invalid; uncomputable: invalid), packs them with the cantools
database and queues :class:`CanFrame` for ``frames()``. Slot items beyond a repeated message's
slots (13 obstacle slots for up to 15 objects, C7) are counted in ``counters.slot_overflow``.
:class:`GatewayNode` puts the host and the gateway on one runner timer."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.can.dbc import database
from eyeq_spi.catalog.can import (
    BASE_NAMES,
    CanMessage,
    CanProtocol,
    CanSignal,
    can_specs,
    protocol,
)
from eyeq_spi.catalog.can_expr import MISSING, compile_expr

Vehicle = Callable[[float], dict[str, Any]]


@dataclass(frozen=True)
class CanFrame:
    time: float
    arbitration_id: int
    data: bytes
    name: str


@dataclass
class GatewayCounters:
    frames: Counter[str] = field(default_factory=Counter)  # per DBC message name
    clamped: Counter[str] = field(default_factory=Counter)  # per signal name
    invalid: Counter[str] = field(default_factory=Counter)  # sent as invalid: out of range
    missing: Counter[str] = field(default_factory=Counter)  # no value: invalid or 0 sent
    stepped: Counter[str] = field(default_factory=Counter)  # valid value moved off the invalid raw
    # slot items with no slot left, per message (C7: 13 obstacle slots for up to 15 objects)
    slot_overflow: Counter[str] = field(default_factory=Counter)


@dataclass
class _Plan:
    message: CanMessage
    period: float
    slots: Callable[[dict[str, Any]], Any] | None
    signals: list[tuple[CanSignal, Callable[[dict[str, Any]], Any] | None]]
    db_messages: list[Any]  # cantools Message per instance
    due: float = 0.0
    sent: int = 0


def physical_to_raw(sig: CanSignal, value: Any, counters: GatewayCounters | None = None,
                    ) -> int | float:
    """The raw value a signal sends for ``value`` (MISSING: its invalid value, or 0)."""
    def note(kind: str) -> None:
        if counters is not None:
            getattr(counters, kind)[sig.name] += 1

    if value is MISSING or value is None:
        note("missing")
        if sig.raw_invalid is not None:
            return sig.raw_invalid
        value = 0.0
    try:
        number = float(value)
    except (TypeError, ValueError):
        note("missing")
        return sig.raw_invalid if sig.raw_invalid is not None else 0
    if not math.isfinite(number):
        note("missing")
        return sig.raw_invalid if sig.raw_invalid is not None else 0
    lo = sig.min if sig.min is not None else -math.inf
    hi = sig.max if sig.max is not None else math.inf
    if not lo <= number <= hi:
        if sig.out_of_range == "invalid" and sig.raw_invalid is not None:
            note("invalid")
            return sig.raw_invalid
        note("clamped")
        number = min(max(number, lo), hi)
    if sig.is_float:
        return number
    raw = round((number - sig.offset) / sig.scale)
    # rounding must not leave the printed range (127.93 -> 127.9375): one raw step back
    step = 1 if sig.scale > 0 else -1
    if sig.max is not None and raw * sig.scale + sig.offset > sig.max + 1e-12:
        raw -= step
    if sig.min is not None and raw * sig.scale + sig.offset < sig.min - 1e-12:
        raw += step
    rlo, rhi = sig.raw_limits
    if not rlo <= raw <= rhi:
        note("clamped")
        raw = min(max(raw, rlo), rhi)
    if raw == sig.raw_invalid and sig.enum is None and (sig.scale != 1 or sig.offset != 0):
        # a measured value that rounds onto the printed invalid raw value (0x729's 12-bit
        # boundaries: FFh = 5.5 deg, inside -20..20) would read as invalid: one raw step
        # towards the value instead, within one raw step as C4 allows
        away = 1 if (number - sig.offset) / sig.scale >= raw else -1
        raw = raw + away if rlo <= raw + away <= rhi else raw - away
        note("stepped")
    return raw


class CanGateway:
    """Sans-IO: ``on_message`` (subscriber), ``get_timer``, ``handle_timer(now)``, ``frames()``."""

    def __init__(self, proto: CanProtocol | str, *, vehicle: Vehicle | None = None,
                 epoch: float = 0.0) -> None:
        self.protocol = protocol(proto) if isinstance(proto, str) else proto
        self.vehicle = vehicle
        self.epoch = epoch  # frame times and ``t`` count from here
        self.counters = GatewayCounters()
        _, mapping = can_specs()
        self._tables = mapping.tables
        self._sources: dict[str, tuple[str, tuple[str, ...]]] = {}
        for alias, text in mapping.sources.items():
            msg, *path = text.split(".")
            self._sources[alias] = (msg, tuple(path))
        names = set(BASE_NAMES) | set(self._sources)
        tables = set(self._tables)
        self._derived: list[tuple[str, Callable[[dict[str, Any]], Any]]] = []
        for dname, dm in mapping.derived:
            self._derived.append((dname, compile_expr(dm.expr, names, tables)))
            names.add(dname)
        db = database(self.protocol.name)
        pm = mapping.protocols.get(self.protocol.name, {})
        self._plans: list[_Plan] = []
        for message in self.protocol.messages:
            mm = pm.get(message.name)
            sigs = [(s, compile_expr(mm.signals[s.name].expr, names, tables)
                     if mm is not None and s.name in mm.signals else None) for s in message.signals]
            slots = compile_expr(mm.slots.expr, names, tables) \
                if mm is not None and mm.slots is not None else None
            self._plans.append(_Plan(message, message.cycle_ms / 1000.0, slots, sigs,
                                     [db.get_message_by_frame_id(fid)
                                      for _, fid, _ in message.instances()]))
        self._latest: dict[str, dict[str, Any]] = {}
        self._queue: list[CanFrame] = []
        self._started = False

    # -- input ------------------------------------------------------------------------------
    def on_message(self, msg: Any) -> None:
        """Host subscriber: keep the newest fields of each decoded DASP message."""
        name = getattr(msg, "name", None)
        if name is None or getattr(msg, "errors", None):
            return
        self._latest[name] = msg.fields

    def start(self, now: float) -> None:
        """Start the cycles (done by the first ``handle_timer`` after a DASP message)."""
        self._started = True
        for plan in self._plans:
            plan.due = now

    # -- timer ------------------------------------------------------------------------------
    def get_timer(self) -> float | None:
        if not self._started:
            return None
        return min(p.due for p in self._plans)

    def poll(self, now: float) -> None:
        """Called by the node wrapper after each input: starts the clock on the first data."""
        if not self._started and self._latest:
            self.start(now)

    def handle_timer(self, now: float) -> None:
        if not self._started:
            self.poll(now)
            if not self._started:
                return
        due = [plan for plan in self._plans if plan.due <= now + 1e-12]
        if not due:
            return
        env = self._environment(now)
        for plan in due:
            self._emit(plan, env, now)
            plan.sent += 1
            plan.due += plan.period
            if plan.due <= now:  # fell behind (a stalled real-time loop): skip, never burst
                plan.due = now + plan.period

    def frames(self) -> list[CanFrame]:
        out, self._queue = self._queue, []
        return out

    # -- evaluation -------------------------------------------------------------------------
    def _environment(self, now: float) -> dict[str, Any]:
        elapsed = now - self.epoch
        env: dict[str, Any] = {"t": elapsed, "__tables__": self._tables}
        env["veh"] = dict(self.vehicle(now)) if self.vehicle is not None else {}
        for alias, (msg, path) in self._sources.items():
            value: Any = self._latest.get(msg)
            for part in path:
                value = value.get(part) if isinstance(value, dict) else None
            env[alias] = value
        for dname, fn in self._derived:
            env[dname] = fn(env)
        return env

    def _emit(self, plan: _Plan, env: dict[str, Any], now: float) -> None:
        env["n"] = plan.sent
        if plan.slots is None:
            items: list[Any] = [None]
        else:
            got = plan.slots(env)
            items = list(got) if isinstance(got, list) else []
            if len(items) > len(plan.db_messages):
                self.counters.slot_overflow[plan.message.name] += len(items) - len(plan.db_messages)
                items = items[: len(plan.db_messages)]
        for index, item in enumerate(items):
            env["i"], env["o"] = index, item
            # an unmapped signal (mapping.yaml `unmapped`, C4) sends its invalid value or
            # physical 0 by design: not counted as missing
            raw = {s.name: physical_to_raw(s, fn(env), self.counters) if fn is not None
                   else physical_to_raw(s, MISSING)
                   for s, fn in plan.signals}
            dbm = plan.db_messages[index]
            data = dbm.encode(raw, scaling=False, padding=False, strict=False)
            self._queue.append(CanFrame(now - self.epoch, dbm.frame_id, bytes(data), dbm.name))
            self.counters.frames[dbm.name] += 1


class GatewayNode:
    """A runner node: the host (or any node) plus the gateway's timer; frames go to ``sink``."""

    def __init__(self, inner: Any, gateway: CanGateway,
                 sink: Callable[[CanFrame], None]) -> None:
        self.inner = inner
        self.gateway = gateway
        self.sink = sink

    def receive_data(self, transfer: bytes, now: float) -> None:
        self.inner.receive_data(transfer, now)
        self.gateway.poll(now)

    def data_to_send(self, now: float) -> list[bytes]:
        return list(self.inner.data_to_send(now))

    def get_timer(self) -> float | None:
        times = [t for t in (self.inner.get_timer(), self.gateway.get_timer()) if t is not None]
        return min(times) if times else None

    def handle_timer(self, now: float) -> None:
        due = self.inner.get_timer()
        if due is not None and due <= now:
            self.inner.handle_timer(now)
        self.gateway.poll(now)
        gateway_timer = self.gateway.get_timer()
        if gateway_timer is not None and gateway_timer <= now:
            self.gateway.handle_timer(now)
            for frame in self.gateway.frames():
                self.sink(frame)
