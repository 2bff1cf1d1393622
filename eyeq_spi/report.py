"""One closing summary for ``demo``, ``host`` and ``sim``: the same JSON schema on every side,
with ``ok`` false and ``problem`` naming the first cause whenever data was lost or corrupted or a
deadline was missed.

Schema (README "Run summaries"): ``side``, ``ok``, ``problem``, ``state``, ``sw``, ``elapsed_s``,
``wall_s``, ``cpu_s``, ``connections``, ``messages`` (received, per name), ``sent`` (per name),
``link`` (the §9.2 counters plus ``lateFrames``, ``duplicateFrames``, ``skippedFrames``,
``resynchronisations``), ``ack_latency_ms`` (``n``, ``p50``, ``p99_9``, ``max`` of our DATA
frames' send -> ACK time), ``transport_aborts``, ``e2e_errors``, ``dasp_counter_gaps``,
``stale_streams``, ``mesp`` (``requests``, ``retries``, ``timeouts``, ``stale_replies``),
``eyeq_resets``, ``versions``, ``boot``, ``transitions``, ``running_vision_since``.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from eyeq_spi.host.host import HostEmulator
from eyeq_spi.host.machine import HostState
from eyeq_spi.link.counters import SpiDiagnosticInfo
from eyeq_spi.sim.eyeq import SimulatedEyeQ
from eyeq_spi.spec.catalog import sw_release_text
from eyeq_spi.transport.connection import TransportConnection

LINK_EXTRA = ("lateFrames", "duplicateFrames", "skippedFrames", "resynchronisations")


def link_view(c: SpiDiagnosticInfo) -> dict[str, int]:
    out = c.seed_view()
    out.update({k: int(getattr(c, k)) for k in LINK_EXTRA})
    return out


def ack_latency_ms(hist: Counter[int]) -> dict[str, float | int]:
    """p50, p99.9 and max of a link's send -> ACK latency histogram (10 µs bins), in ms."""
    n = sum(hist.values())
    if not n:
        return {"n": 0}
    out: dict[str, float | int] = {"n": n}
    bins = sorted(hist.items())
    for name, q in (("p50", 0.5), ("p99_9", 0.999)):
        seen, rank = 0, q * n
        for b, c in bins:
            seen += c
            if seen >= rank:
                out[name] = round(b / 100, 2)
                break
    out["max"] = round(bins[-1][0] / 100, 2)
    return out


def _losses(s: dict[str, Any]) -> str | None:
    """The first data loss, corruption or missed deadline in a summary, in words."""
    link = s["link"]
    checks: list[tuple[bool, str]] = [
        (s["e2e_errors"] > 0, f"{s['e2e_errors']} E2E errors"),
        (link["sendFailedErrorCounter"] > 0,
         f"{link['sendFailedErrorCounter']} send failures (frames not ACKed in time)"),
        (sum(s["transport_aborts"].values()) > 0,
         f"transport aborts {s['transport_aborts']}"),
        (s["dasp_counter_gaps"] > 0, f"{s['dasp_counter_gaps']} DASP counter gaps"),
        (bool(s["stale_streams"]), f"stale streams: {', '.join(s['stale_streams'])}"),
        (s["mesp"]["timeouts"] > 0, f"{s['mesp']['timeouts']} MESP timeouts"),
    ]
    return next((why for bad, why in checks if bad), None)


def _finish(s: dict[str, Any], first_problem: str | None) -> dict[str, Any]:
    s["problem"] = first_problem or _losses(s)
    s["ok"] = s["problem"] is None
    s.setdefault("scheduling", None)  # host, sim: the CPU policy obtained (runner/sched.py)
    s.setdefault("sessions", [])  # sim: one entry per host served
    s.setdefault("link_lost", None)  # host: why the link was lost, if it was
    return s


def _aborts(conn: TransportConnection) -> dict[str, int]:
    return {k: int(v) for k, v in conn.counters.transferAborts.items() if v}


def host_summary(host: HostEmulator, *, side: str, elapsed: float, wall: float, cpu: float,
                 running_since: float | None, left_running: list[float],
                 link_lost: str | None = None, connections: int = 1,
                 interrupted: bool = False, t0: float = 0.0) -> dict[str, Any]:
    """The summary of a host emulator run (``demo`` or ``host``). Times are seconds since
    ``t0``, the start of the run on the host's clock."""
    names = [m.name for m in host.codec.cat.messages if m.exists_in(host.sw) or
             m.protocol != "DASP"]
    messages = {n: int(host.counters.received.get(n, 0)) for n in names}
    messages["HOST_VEH_STATE_MSG"] = int(host.counters.sent.get("HOST_VEH_STATE_MSG", 0))
    stale = sorted(set(host.counters.stale_events) | host.stale_streams)
    s: dict[str, Any] = {
        "side": side, "state": host.state.value, "sw": sw_release_text(host.sw),
        "elapsed_s": round(elapsed, 6), "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
        "connections": connections, "interrupted": interrupted,
        "messages": messages, "sent": {k: int(v) for k, v in host.counters.sent.items()},
        "link": link_view(host.conn.link.counters),
        "ack_latency_ms": ack_latency_ms(host.conn.link.ack_latency),
        "transport_aborts": _aborts(host.conn),
        "e2e_errors": host.counters.e2e_errors,
        "dasp_counter_gaps": host.counters.dasp_counter_gaps,
        "decode_errors": host.counters.decode_errors,
        "stale_streams": stale,
        "mesp": {"requests": host.mesp.counters.requests, "retries": host.mesp.counters.retries,
                 "timeouts": host.mesp.counters.timeouts,
                 "stale_replies": host.mesp.counters.stale_replies},
        "eyeq_resets": host.counters.eyeq_resets,
        "versions": host.versions, "boot": host.boot_info,
        "transitions": [
            {"t": round(t.time - t0, 4), "from": t.src.value, "event": t.event.value,
             "to": t.dst.value, "detail": t.detail} for t in host.transitions
        ],
        "running_vision_since": None if running_since is None else round(running_since, 4),
    }
    first = None
    if link_lost:
        first = "link lost"
    elif host.problem:
        first = host.problem
    elif running_since is None:
        first = f"Running Vision not reached (state {host.state.value})"
    elif left_running:
        first = f"left Running Vision at {left_running[0]:.3f} s"
    return _finish(s, first)


def sim_summary(sim: SimulatedEyeQ, *, elapsed: float, wall: float, cpu: float,
                link_lost: str | None = None, connections: int = 1,
                interrupted: bool = False, t0: float = 0.0) -> dict[str, Any]:
    """The summary of a simulated EyeQ run (``sim``), for the last host it served plus totals.
    Times are seconds since ``t0``, the start of the run on the simulator's clock."""
    c = sim.counters
    s: dict[str, Any] = {
        "side": "sim", "state": f"0x{sim.main_state:02X}", "sw": sw_release_text(sim.sw),
        "elapsed_s": round(elapsed, 6), "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
        "connections": connections, "interrupted": interrupted,
        "messages": {k: int(v) for k, v in c.received.items()},
        "sent": {k: int(v) for k, v in c.sent.items()},
        "link": link_view(sim.conn.link.counters),
        "ack_latency_ms": ack_latency_ms(sim.conn.link.ack_latency),
        "transport_aborts": _aborts(sim.conn),
        "e2e_errors": c.e2e_errors,
        "dasp_counter_gaps": c.counter_gaps,
        "decode_errors": c.bad_hdr_total,
        "stale_streams": ["HOST_VEH_STATE_MSG"] if c.veh_state_stale else [],
        "mesp": {"requests": c.mesp_requests, "retries": 0, "timeouts": 0, "stale_replies": 0},
        "eyeq_resets": c.boots - connections if c.boots > connections else 0,
        "versions": {"eyeqSwVersionMajor": sim.sw_version[0],
                     "eyeqSwVersionMinor": sim.sw_version[1]},
        "boot": {"boots": c.boots}, "transitions": [],
        "running_vision_since": (None if sim.running_since is None
                                 else round(sim.running_since - t0, 4)),
    }
    # the host leaving ends a session; it is not a loss on the EyeQ side (it serves the next)
    return _finish(s, None)


def running_state(host: HostEmulator) -> bool:
    return host.state is HostState.RUNNING_VISION
