"""Where gateway frames go (``--can-out``, docs/can.md): a python-can bus (``virtual[:CHANNEL]``,
``INTERFACE:CHANNEL``) or a python-can log writer chosen by suffix; the only I/O of the CAN
package."""

from __future__ import annotations

import atexit
import contextlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from eyeq_spi.can.gateway import CanFrame, CanGateway, GatewayNode
from eyeq_spi.can.logs import bus_of
from eyeq_spi.errors import MissingExtra, OutputError, UsageError

LOG_SUFFIXES = (".blf", ".asc", ".mf4", ".log", ".trc", ".csv")


def _can() -> Any:
    try:
        import can
    except ImportError as exc:
        raise MissingExtra("can", "CAN output needs python-can") from exc
    return can


@dataclass
class CanSink:
    """Callable sink for :class:`CanFrame`; counts send errors instead of raising."""

    target: str
    kind: str  # "bus" | "log"
    handle: Any
    sent: int = 0
    errors: int = 0
    closed: bool = field(default=False)

    def __call__(self, frame: CanFrame) -> None:
        can = _can()
        msg = can.Message(timestamp=frame.time, arbitration_id=frame.arbitration_id,
                          data=frame.data, is_extended_id=False, dlc=len(frame.data))
        try:
            if self.kind == "bus":
                self.handle.send(msg, timeout=0.0)
            else:
                self.handle.on_message_received(msg)
            self.sent += 1
        except (can.CanError, OSError, ValueError):  # a full queue, a gone interface
            self.errors += 1

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        with contextlib.suppress(Exception):  # closing must never raise at exit
            if self.kind == "bus":
                self.handle.shutdown()
            else:
                self.handle.stop()


def open_target(target: str) -> CanSink:
    """Open a ``--can-out`` target (see the module docstring)."""
    can = _can()
    if not target:
        raise UsageError("--can-out needs a target: virtual, socketcan:vcan0 or a log file")
    suffix = Path(target).suffix.lower()
    if suffix in LOG_SUFFIXES:
        try:
            writer = can.Logger(target)
        except ImportError as exc:
            raise MissingExtra("can,export", f"{target}: {suffix} logs need {exc.name or exc}"
                               ) from exc
        except (OSError, ValueError) as exc:
            raise OutputError(f"cannot write CAN log {target}: {exc}") from exc
        return CanSink(target, "log", writer)
    interface, _, channel = target.partition(":")
    if "." in interface or "/" in interface:
        raise UsageError(f"--can-out {target!r}: a log file needs one of the suffixes "
                         f"{', '.join(LOG_SUFFIXES)}; a bus is INTERFACE[:CHANNEL]")
    return CanSink(target, "bus", bus_of(can, target, interface, channel or "eyeq-spi"))


@dataclass
class CanOutput:
    gateway: CanGateway
    sink: CanSink
    node: GatewayNode

    def close(self) -> None:
        self.sink.close()

    def summary(self) -> dict[str, Any]:
        counters = self.gateway.counters
        return {"target": self.sink.target, "protocol": self.gateway.protocol.name,
                "frames": sum(counters.frames.values()), "send_errors": self.sink.errors,
                "clamped": sum(counters.clamped.values()),
                "invalid": sum(counters.invalid.values()),
                # objects beyond the 13 ExtLogData2 obstacle slots (C7), not sent
                "slot_overflow": dict(counters.slot_overflow)}


def attach(host: Any, runner: Any, *, target: str, protocol: str) -> CanOutput:
    """Subscribe a gateway to ``host``'s decoded DASP messages and put it on ``runner``'s clock:
    the host's node in the runner becomes a :class:`GatewayNode` wrapping it. The sink is closed
    at exit (log files are finalised) or by ``close()``."""
    clock = getattr(runner, "clock", None)
    epoch = float(clock()) if callable(clock) else float(getattr(runner, "now", 0.0))
    scenario = getattr(host, "scenario", None)
    vehicle = scenario.signals if scenario is not None else None
    gateway = CanGateway(protocol, vehicle=vehicle, epoch=epoch)
    sink = open_target(target)
    node = GatewayNode(host, gateway, sink)
    host.subscribe(gateway.on_message)
    if hasattr(runner, "nodes"):
        runner.nodes = [(node, a) if n is host else (n, a) for n, a in runner.nodes]
    elif getattr(runner, "node", None) is host:
        runner.node = node
    else:
        sink.close()
        raise UsageError("--can-out: this runner has no host node to attach the gateway to")
    out = CanOutput(gateway, sink, node)
    atexit.register(out.close)
    return out
