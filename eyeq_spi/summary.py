"""One closing summary for every run: ``demo``, ``host``, ``sim`` and ``replay`` print the same
JSON object (the keys of :data:`KEYS`, described in docs/emulator.md, "Run summaries"), with
``ok`` false and ``problem`` naming the first cause whenever data was lost or corrupted or a
deadline was missed. A MESP reply that never came is a timeout on every side that can know it
(M6); requests an EyeQ reset left unanswered are ``mesp.abandoned``, not a loss."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

from eyeq_spi.catalog.messages import sw_release_text
from eyeq_spi.host.host import HostEmulator
from eyeq_spi.host.link_health import with_link_cause
from eyeq_spi.host.machine import HostState
from eyeq_spi.link.counters import SpiDiagnosticInfo
from eyeq_spi.link.frame import FRAME_SIZE, FrameCodec, FrameKind
from eyeq_spi.sim.eyeq import SimulatedEyeQ

LINK_EXTRA = ("lateFrames", "duplicateFrames", "skippedFrames", "resynchronisations")

# Every summary has exactly these keys, in this order (docs/emulator.md, "Run summaries").
KEYS = (
    "side", "ok", "problem", "address", "state", "sw", "elapsed_s", "wall_s", "cpu_s",
    "connections", "interrupted", "received", "sent", "link", "ack_latency_ms",
    "transport_aborts", "e2e_errors", "dasp_counter_gaps", "decode_errors", "stale_streams",
    "mesp", "eyeq_resets", "eyeq_reset_causes", "versions", "boot", "transitions",
    "running_vision_since", "sessions", "link_lost", "left_at_link_loss", "scheduling",
    "replay", "can", "spi",
)
# a sim session: the summary of one host served, without what belongs to the whole run
SESSION_KEYS = ("began_s", "ended_s", "ok", "problem", "state", "received", "sent", "link",
                "ack_latency_ms", "transport_aborts", "e2e_errors", "dasp_counter_gaps",
                "decode_errors", "stale_streams", "mesp", "eyeq_resets", "eyeq_reset_causes",
                "versions", "boot", "running_vision_since", "link_lost", "left_at_link_loss")


def link_view(counters: SpiDiagnosticInfo, restarts_answered: int = 0) -> dict[str, int]:
    """The link's counters; ``restarts_answered``: resynchronisations that were the peer's
    restart after a reset we asked for (L10), counted in ``eyeq_resets`` instead."""
    out = counters.seed_view()
    out.update({k: int(getattr(counters, k)) for k in LINK_EXTRA})
    out["resynchronisations"] = max(0, out["resynchronisations"] - restarts_answered)
    return out


def reset_causes(asked: int, not_asked: int) -> dict[str, int]:
    """``eyeq_reset_causes``: every reset of the EyeQ by cause (``eyeq_resets`` is the sum)."""
    return {"asked_by_host": asked, "not_asked": not_asked}


def ack_latency_ms(hist: Counter[int]) -> dict[str, float | int]:
    """p50, p99.9 and max of a link's send -> ACK latency histogram (10 µs bins), in ms."""
    total = sum(hist.values())
    if not total:
        return {"n": 0}
    out: dict[str, float | int] = {"n": total}
    bins = sorted(hist.items())
    for name, quantile in (("p50", 0.5), ("p99_9", 0.999)):
        seen, rank = 0, quantile * total
        for latency_bin, count in bins:
            seen += count
            if seen >= rank:
                out[name] = round(latency_bin / 100, 2)
                break
    out["max"] = round(bins[-1][0] / 100, 2)
    return out


def _losses(summary: dict[str, Any]) -> str | None:
    """Every data loss, corruption or missed deadline in a summary, in words, causes before
    their consequences (a send failure aborts a transfer, which leaves a DASP counter gap, after
    which D5 rejects the next protected structure)."""
    link = summary["link"]
    mesp = summary["mesp"]
    timeouts = mesp.get("timeouts") or 0
    aborts = sum(summary["transport_aborts"].values())
    checks: list[tuple[bool, str]] = [
        (link.get("sendFailedErrorCounter", 0) > 0,
         f"{link.get('sendFailedErrorCounter')} send failures (frames not ACKed in time)"),
        (aborts > 0, f"transport aborts {summary['transport_aborts']}"),
        (summary["dasp_counter_gaps"] > 0, f"{summary['dasp_counter_gaps']} DASP counter gaps"),
        (summary["e2e_errors"] > 0, f"{summary['e2e_errors']} E2E errors"
         + (" (after the gaps: D5 rejects a structure whose rolling counter jumped)"
            if summary["dasp_counter_gaps"] > 0 else "")),
        (bool(summary["stale_streams"]), f"stale streams: {', '.join(summary['stale_streams'])}"),
        (timeouts > 0, f"{timeouts} MESP timeouts"),
    ]
    said = [why for bad, why in checks if bad]
    return "; ".join(said) if said else None


def finish(summary: dict[str, Any], first_problem: str | None) -> dict[str, Any]:
    """Judge a summary (``problem``, ``ok``) and give it exactly the keys of :data:`KEYS`."""
    summary["problem"] = first_problem or _losses(summary)
    summary["ok"] = summary["problem"] is None
    return {k: summary.get(k) for k in KEYS} | {
        "sessions": summary.get("sessions") or [], "received": summary.get("received") or {},
        "sent": summary.get("sent") or {}}


def _mesp(requests: int | None, timeouts: int | None) -> dict[str, int | None]:
    """``mesp`` of a side that counts only requests and timeouts (retries, abandoned and stale
    replies are the host's count)."""
    return {"requests": requests, "retries": None, "timeouts": timeouts, "abandoned": None,
            "stale_replies": None}


def _versions(sim: SimulatedEyeQ) -> dict[str, int]:
    return {"eyeqSwVersionMajor": sim.sw_version[0], "eyeqSwVersionMinor": sim.sw_version[1]}


def host_mesp(host: HostEmulator, eyeq: SimulatedEyeQ | None = None) -> dict[str, int]:
    counters = host.mesp.counters
    dropped = 0 if eyeq is None else eyeq.counters.mesp_replies_dropped
    return {"requests": counters.requests, "retries": counters.retries,
            "timeouts": max(counters.timeouts, dropped), "abandoned": counters.abandoned,
            "stale_replies": counters.stale_replies}


@dataclass
class LeftAtLinkLoss:
    """What lost connections left behind on our side (L10: a new connection is a new EyeQ):
    messages never ACKed and transfers half received, reported apart (``left_at_link_loss``)."""

    messages: int = 0
    transfers: int = 0


def _dropped(host: HostEmulator) -> tuple[int, int]:
    """Messages and transfers a reset of the host's link and transport drops."""
    return (host.conn.link.counters.sendFailedErrorCounter,
            host.conn.counters.transferAborts["reset"])


def new_connection(host: HostEmulator, now: float, left: LeftAtLinkLoss) -> None:
    """The host on a new connection (:meth:`HostEmulator.link_restarted`), with what the old
    one left counted in ``left``."""
    messages, transfers = _dropped(host)
    host.link_restarted(now)
    after = _dropped(host)
    left.messages += after[0] - messages
    left.transfers += after[1] - transfers


def _without_left(summary: dict[str, Any], left: LeftAtLinkLoss | None) -> None:
    """Take what lost connections left out of the counts of the connections that followed."""
    if left is None:
        return
    link = summary["link"]
    if "sendFailedErrorCounter" in link:
        link["sendFailedErrorCounter"] = max(0, link["sendFailedErrorCounter"] - left.messages)
    aborts = summary["transport_aborts"]
    if "reset" in aborts:
        aborts["reset"] = max(0, aborts["reset"] - left.transfers)
        if not aborts["reset"]:
            del aborts["reset"]
    summary["left_at_link_loss"] = asdict(left)


class ClockedAcks:
    """A tap of an in-process run (node 0 the host) that reads the send -> ACK latency of the
    host's DATA frames on ``clock`` as each transfer is handed over: the ``ack_latency_ms`` of a
    real-time ``demo``. ``then``: another tap every transfer goes on to (the capture)."""

    def __init__(self, clock: Callable[[], float], then: Any = None) -> None:
        self.clock = clock
        self.then = then
        self.codec = FrameCodec()
        self.sent: dict[int, float] = {}  # NUM -> the clock when the host handed it over
        self.hist: Counter[int] = Counter()  # 10 µs bin -> frames ACKed, as the link's

    def __call__(self, node: int, time_s: float, transfer: bytes) -> None:
        if self.then is not None:
            self.then(node, time_s, transfer)
        if len(transfer) != FRAME_SIZE:
            return
        kind, _, rsp, num, crc_ok = self.codec.check(transfer)
        if not crc_ok:
            return
        if node == 0 and kind == FrameKind.DATA:
            self.sent[num] = self.clock()
        elif node == 1 and kind == FrameKind.ACK and (sent := self.sent.pop(rsp, None)):
            self.hist[int((self.clock() - sent) * 1e5)] += 1


@dataclass
class RunningVision:
    """Whether the host reached Running Vision and held it: when it entered (``since``, None
    while outside) and every time it left (``left``), for every kind of run."""

    since: float | None = None
    left: list[float] = field(default_factory=list)

    def update(self, host: HostEmulator, time_s: float) -> None:
        running = host.state is HostState.RUNNING_VISION
        if running and self.since is None:
            self.since = time_s
        elif not running and self.since is not None:
            self.left.append(time_s)
            self.since = None

    def reset(self) -> None:
        """A new connection: judged again from its start."""
        self.since, self.left = None, []


def host_summary(host: HostEmulator, *, side: str, elapsed: float, wall: float, cpu: float,
                 running_since: float | None, left_running: list[float],
                 link_lost: str | None = None, connections: int = 1,
                 interrupted: bool = False, t0: float = 0.0, address: str | None = None,
                 scheduling: str | None = None,
                 eyeq: SimulatedEyeQ | None = None,
                 left: LeftAtLinkLoss | None = None) -> dict[str, Any]:
    """The summary of a host emulator run (``demo``, ``host``, ``replay --into-host``); times
    are seconds since ``t0``. ``eyeq``: the simulated EyeQ of an in-process run, whose dropped
    replies are timeouts too. ``left``: what lost connections left (:func:`new_connection`)."""
    names = [m.name for m in host.codec.cat.messages
             if m.direction == "e2h" and (m.exists_in(host.sw) or m.protocol != "DASP")]
    received = {n: int(host.counters.received.get(n, 0)) for n in names}
    received.update({k: int(v) for k, v in host.counters.received.items()})
    stale = sorted(set(host.counters.stale_events) | host.stale_streams)
    summary: dict[str, Any] = {
        "side": side, "address": address, "state": host.state.value,
        "sw": sw_release_text(host.sw),
        "elapsed_s": round(elapsed, 6), "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
        "connections": connections, "interrupted": interrupted,
        "received": dict(sorted(received.items())),
        "sent": {k: int(v) for k, v in sorted(host.counters.sent.items())},
        "link": link_view(host.conn.link.counters, host.counters.restarts_answered),
        "ack_latency_ms": ack_latency_ms(host.conn.link.ack_latency),
        "transport_aborts": {k: int(v) for k, v in host.conn.counters.transferAborts.items()
                             if v},
        "e2e_errors": host.counters.e2e_errors,
        "dasp_counter_gaps": host.counters.dasp_counter_gaps,
        "decode_errors": host.counters.decode_errors,
        "stale_streams": stale,
        "mesp": host_mesp(host, eyeq),
        # the host's own resets (EEPROM, boot failures) and those it detected
        "eyeq_resets": host.counters.eyeq_resets + host.counters.eyeq_resets_asked,
        "eyeq_reset_causes": reset_causes(host.counters.eyeq_resets_asked,
                                          host.counters.eyeq_resets),
        "versions": host.versions, "boot": host.boot_info,
        "transitions": [
            {"t": round(t.time - t0, 4), "from": t.src.value, "event": t.event.value,
             "to": t.dst.value, "detail": t.detail} for t in host.transitions
        ],
        "running_vision_since": None if running_since is None else round(running_since, 4),
        "link_lost": link_lost, "scheduling": scheduling,
    }
    _without_left(summary, left)
    first = None
    gave_up = host.state in (HostState.FAILED, HostState.BOOT_FAILED)  # why, not "link lost"
    if link_lost and not (gave_up and host.problem):
        first = "link lost"
    elif host.problem:
        first = host.problem
    elif running_since is None:
        first = f"Running Vision not reached (state {host.state.value})"
    elif left_running:
        first = f"left Running Vision at {left_running[0]:.3f} s"
    if first is not None and first != "link lost":  # a bad link is not a bad camera
        first = with_link_cause(first, host.conn.link.counters)
    return finish(summary, first)


# -- sim: per host served and in total -------------------------------------------------------

def _sim_counts(sim: SimulatedEyeQ) -> dict[str, Any]:
    """The simulator's counts since it was made (they run on across power-ups)."""
    counters = sim.counters
    return {
        "received": {k: int(v) for k, v in counters.received.items()},
        "sent": {k: int(v) for k, v in counters.sent.items()},
        "link": link_view(sim.conn.link.counters),
        "transport_aborts": {k: int(v) for k, v in sim.conn.counters.transferAborts.items()},
        "e2e_errors": counters.e2e_errors, "dasp_counter_gaps": counters.counter_gaps,
        "decode_errors": counters.bad_hdr_total, "stale": counters.veh_state_stale,
        "mesp": {"requests": counters.mesp_requests,
                 "timeouts": counters.mesp_replies_dropped + counters.mesp_replies_late},
        "boots": counters.boots, "self_resets": counters.self_resets,
        "vision_switches": counters.vision_switches,
        "hist": Counter(sim.conn.link.ack_latency),
    }


GAUGES = frozenset({"busyFrames"})  # link values that are a level now, not a count


def _minus(now: Any, before: Any) -> Any:
    """``now - before`` key by key (counts only grow); a gauge is its value now."""
    if isinstance(now, dict):
        return {k: v if k in GAUGES else _minus(v, before.get(k)) for k, v in now.items()}
    return now - (before or 0)


def _nonzero(counts: dict[str, int]) -> dict[str, int]:
    return {k: v for k, v in sorted(counts.items()) if v}


class SimSessions:
    """The summaries of the hosts a ``sim`` run serves, one per connection, each with that
    host's counts only; times are seconds since ``t0`` on the simulator's clock."""

    def __init__(self, t0: float = 0.0) -> None:
        self.t0 = t0
        self.sessions: list[dict[str, Any]] = []
        self._last: tuple[SimulatedEyeQ, dict[str, Any]] | None = None
        self._begun: tuple[SimulatedEyeQ, dict[str, Any]] | None = None

    def begin(self, sim: SimulatedEyeQ) -> None:
        """A host connected and ``sim`` was powered up for it; the power-up's reset (L10) drops what
        the link still held for the host before, which is no loss of this session."""
        self._begun = (sim, _sim_counts(sim))

    def add(self, sim: SimulatedEyeQ, *, began: float, ended: float,
            link_lost: str | None, not_taken: int = 0,
            failed_when_heard: int | None = None) -> dict[str, Any]:
        """Close the session of the host just served and return its summary. ``not_taken``:
        transfers the adapter dropped with its connection; ``failed_when_heard``: send failures when
        the host was last heard (later ones went to a host that was gone: not a loss)."""
        now = _sim_counts(sim)
        counts = now if self._last is None or self._last[0] is not sim \
            else _minus(now, self._last[1])
        if self._begun is not None and self._begun[0] is sim:  # link counts from the power-up
            for key in ("link", "transport_aborts"):
                counts[key] = _minus(now[key], self._begun[1][key])
        self._last, self._begun = (sim, now), None
        gone = 0 if link_lost is None or failed_when_heard is None else max(
            0, sim.conn.link.counters.sendFailedErrorCounter - failed_when_heard)
        counts["link"]["sendFailedErrorCounter"] -= gone
        session: dict[str, Any] = {
            "began_s": round(began, 3), "ended_s": round(ended, 3),
            "state": f"0x{sim.main_state:02X}",
            "received": _nonzero(counts["received"]), "sent": _nonzero(counts["sent"]),
            "link": counts["link"], "ack_latency_ms": ack_latency_ms(counts["hist"]),
            "transport_aborts": _nonzero(counts["transport_aborts"]),
            "e2e_errors": counts["e2e_errors"], "dasp_counter_gaps": counts["dasp_counter_gaps"],
            "decode_errors": counts["decode_errors"],
            "stale_streams": ["HOST_VEH_STATE_MSG"] if counts["stale"] else [],
            "mesp": _mesp(counts["mesp"]["requests"], counts["mesp"]["timeouts"]),
            # the connection's own power-up is no reset; its own resets (reset_at) no host
            # asked for; every other boot, and every accepted Switch to Vision (L10), it did
            "eyeq_resets": max(0, counts["boots"] - 1) + counts["vision_switches"],
            "eyeq_reset_causes": reset_causes(
                max(0, counts["boots"] - 1 - counts["self_resets"]) + counts["vision_switches"],
                counts["self_resets"]),
            "versions": _versions(sim), "boot": {"boots": counts["boots"]},
            "running_vision_since": (None if sim.running_since is None
                                     else round(sim.running_since - self.t0, 4)),
            "link_lost": link_lost,
            # what the host left: our frames it never ACKed, its transfers the EyeQ never read
            # (null: the session did not end by link loss)
            "left_at_link_loss": None if link_lost is None else {
                "frames": sim.conn.link.in_flight + gone, "transfers": not_taken},
        }
        # the host leaving ends a session; it is not a loss on the EyeQ side (it serves the next)
        session["problem"] = _losses(session)
        session["ok"] = session["problem"] is None
        session["_ack_hist"] = counts["hist"]  # for the totals; sim_summary drops it
        self.sessions.append(session)
        return session


def _add(total: Any, part: Any) -> Any:
    """Counts summed key by key (None: not counted on this side)."""
    if isinstance(part, dict):
        out = dict(total or {})
        for key, value in part.items():
            out[key] = _add(out.get(key), value)
        return out
    if part is None:
        return total
    return (total or 0) + part


def sim_summary(sim: SimulatedEyeQ, sessions: list[dict[str, Any]], *, elapsed: float,
                wall: float, cpu: float, interrupted: bool = False, address: str | None = None,
                scheduling: str | None = None, problem: str | None = None) -> dict[str, Any]:
    """The summary of a ``sim`` run: every host served (from :class:`SimSessions`) and their
    totals; ``sim`` is the last one served (or an idle one)."""
    hist: Counter[int] = Counter()
    summary: dict[str, Any] = {
        "side": "sim", "address": address, "sw": sw_release_text(sim.sw),
        "elapsed_s": round(elapsed, 6), "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
        "connections": len(sessions), "interrupted": interrupted,
        "received": {}, "sent": {}, "link": link_view(SpiDiagnosticInfo()),
        "transport_aborts": {}, "e2e_errors": 0, "dasp_counter_gaps": 0, "decode_errors": 0,
        "stale_streams": [], "eyeq_resets": 0, "eyeq_reset_causes": reset_causes(0, 0),
        "transitions": [],
        "mesp": _mesp(0, 0), "state": f"0x{sim.main_state:02X}", "versions": _versions(sim),
        "boot": {"boots": 0}, "scheduling": scheduling,
    }
    for sess in sessions:
        hist.update(sess.pop("_ack_hist", Counter()))
        for key in ("received", "sent", "link", "transport_aborts", "e2e_errors",
                    "dasp_counter_gaps", "decode_errors", "eyeq_resets", "eyeq_reset_causes",
                    "mesp", "boot"):
            summary[key] = _add(summary[key], sess[key])
        stale = set(summary["stale_streams"]) | set(sess["stale_streams"])
        summary["stale_streams"] = sorted(stale)
        summary["state"], summary["versions"] = sess["state"], sess["versions"]
        summary["running_vision_since"] = sess["running_vision_since"]
        summary["link_lost"] = sess["link_lost"]
    for gauge in GAUGES & set(summary["link"]):  # a level of the last host, not a sum over hosts
        summary["link"][gauge] = sessions[-1]["link"].get(gauge, 0) if sessions else 0
    summary["ack_latency_ms"] = ack_latency_ms(hist)
    summary["sessions"] = [{k: sess[k] for k in SESSION_KEYS} for sess in sessions]
    return finish(summary, problem)


# -- replay: a capture's EyeQ channel played to a host -----------------------------------------

def replay_port_summary(replay: dict[str, Any], *, address: str, wall: float, cpu: float,
                        link: dict[str, int], link_lost: str | None, sent: dict[str, int],
                        interrupted: bool = False, connections: int = 1,
                        scheduling: str | None = None) -> dict[str, Any]:
    """The summary of ``replay --port``/``--listen``: judged on what we see (the capture played
    to the end, the link held, every played frame ACKed, none NAKed)."""
    naks = sum(replay["host_naks"].values())
    unanswered = replay["played"] - replay["host_acks"] - naks
    summary: dict[str, Any] = {
        "side": "replay", "address": address, "sw": replay.get("sw"),
        "elapsed_s": round(wall, 6), "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
        "connections": connections, "interrupted": interrupted,
        "received": replay["host_messages"], "sent": sent, "link": link,
        "ack_latency_ms": {"n": 0}, "transport_aborts": {}, "e2e_errors": 0,
        "dasp_counter_gaps": 0, "decode_errors": replay.get("decode_errors", 0),
        "stale_streams": [],
        "mesp": _mesp(None, None),
        "eyeq_resets": replay["reset_line_pulls"],
        "eyeq_reset_causes": reset_causes(replay["reset_line_pulls"], 0), "transitions": [],
        "link_lost": link_lost, "scheduling": scheduling, "replay": replay,
    }  # state, versions, boot, running_vision_since: none to report (null)
    first = None
    if interrupted:
        first = "interrupted"
    elif link_lost:
        first = "link lost"
    elif not replay["complete"]:
        first = "the capture was not played to the end"
    elif naks:
        first = f"the host NAKed {naks} played frames: {replay['host_naks']}"
    elif unanswered > 0:
        first = f"{unanswered} of {replay['played']} played frames not ACKed by the host"
    return finish(summary, first)


# -- text ---------------------------------------------------------------------------------------

def _short(name: str) -> str:
    return name.replace("EYEQ_", "").replace("_MSG", "")


def _counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{_short(k)} {v}" for k, v in sorted(counts.items()) if v) or "nothing"


def _state_text(state: str) -> str:
    """A host state as it is; the EyeQ's Main_State with its name from specs/ (``0x02
    RUNNING_VISION``)."""
    if not state.startswith("0x"):
        return state
    from eyeq_spi.catalog.messages import catalog

    enum = catalog().enums.get("main_state")
    value = enum.values.get(int(state, 16)) if enum is not None else None
    return state if value is None else f"{state} {value.name}"


def format_summary(out: dict[str, Any]) -> str:
    """The readable block of a summary: the same content as its JSON, one topic a line."""
    state = "" if out["state"] is None else f"state {_state_text(out['state'])}, "
    lines = [f"{out['side']}: {'OK' if out['ok'] else 'NOT OK'} - {state}"
             f"SW {out['sw']}, {out['elapsed_s']:.2f} s (wall {out['wall_s']:.2f} s, "
             f"CPU {out['cpu_s']:.2f} s), connections {out['connections']}"]
    if out["address"]:
        lines.append(f"  address: {out['address']}")
    if out["problem"]:
        lines.append(f"  problem: {out['problem']}")
    link = out["link"]
    lines.append("  link: " + ", ".join(f"{k} {v}" for k, v in link.items() if v)
                 if any(link.values()) else "  link: no errors")
    mesp = out["mesp"]
    timeouts = "-" if mesp["timeouts"] is None else mesp["timeouts"]
    lines.append(f"  E2E errors {out['e2e_errors']}, DASP counter gaps "
                 f"{out['dasp_counter_gaps']}, transport aborts "
                 f"{out['transport_aborts'] or 'none'}, stale "
                 f"{', '.join(out['stale_streams']) or 'none'}, MESP timeouts {timeouts}"
                 + (f" ({mesp['abandoned']} requests abandoned at EyeQ resets)"
                    if mesp.get("abandoned") else ""))
    left = out.get("left_at_link_loss")
    if left and any(left.values()):
        lines.append(f"  left at link loss (the lost connection's, not an error): "
                     f"{left['messages']} messages unsent or not ACKed, "
                     f"{left['transfers']} transfers half received")
    causes = out.get("eyeq_reset_causes")
    if out.get("eyeq_resets") and causes:
        lines.append(f"  EyeQ resets {out['eyeq_resets']}: asked by the host "
                     f"{causes['asked_by_host']}, not asked {causes['not_asked']}")
    if out.get("scheduling"):  # host, sim and replay to a port; the in-process demo has none
        lines.append(f"  scheduling: {out['scheduling']}")
    lines.append(f"  received: {_counts(out['received'])}")
    lines.append(f"  sent: {_counts(out['sent'])}")
    for number, sess in enumerate(out["sessions"], 1):
        lines.append(_session_line(number, sess))
    can = out.get("can")
    if can:
        over = ", ".join(f"{k} {v}" for k, v in can["slot_overflow"].items())
        lines.append(f"  CAN {can['protocol']} -> {can['target']}: {can['frames']} frames, "
                     f"send errors {can['send_errors']}, clamped {can['clamped']}, "
                     f"sent invalid {can['invalid']}"
                     + (f", objects beyond the slots (not sent) {over}" if over else ""))
    spi = out.get("spi")
    if spi:
        from eyeq_spi.catalog.link import spec_file
        from eyeq_spi.phy.spi import report_text

        ack_timeout_ms = float(spec_file("link.yaml")["timing"]["ackTimeout"]) * 1e3
        lines.append(report_text(spi, ack_timeout_ms))
    rep = out.get("replay")
    if rep:
        lines.append(f"  replay: played {rep['played']} frames"
                     f"{'' if rep['complete'] else ' (not to the end)'}, host ACKs "
                     f"{rep['host_acks']}, host NAKs {sum(rep['host_naks'].values())}")
    return "\n".join(_wrap(line) for line in lines)


def _session_line(number: int, sess: dict[str, Any]) -> str:
    """One host a ``sim`` served: its verdict and, when its connection broke off, when and what
    it left in flight."""
    verdict = "OK" if sess["ok"] else f"NOT OK ({sess['problem']})"
    line = (f"  host {number}: {sess['began_s']:.2f}-{sess['ended_s']:.2f} s, {verdict}, "
            f"received {sum(sess['received'].values())}, sent {sum(sess['sent'].values())}")
    left = sess.get("left_at_link_loss")
    if sess["link_lost"] is None:
        return line + ", served to the end of the run"
    line += f", the host went away at {sess['ended_s']:.2f} s ({sess['link_lost']})"
    if left and (left["frames"] or left["transfers"]):
        line += (f", mid-session, leaving {left['frames']} of our frames not ACKed and "
                 f"{left['transfers']} of its transfers unread")
    return line


def _wrap(line: str, width: int = 80) -> str:
    """A summary line folded between words to fit 80 columns, continuation lines indented."""
    import re
    import textwrap

    if len(line) <= width:
        return line
    lead = len(line) - len(line.lstrip())
    # fold only after a comma or a colon: "DIAGNOSTIC 94" or "MESP timeouts 0" stays whole
    glued = re.sub(r"(?<![,:]) ", "\u00a0", line[lead:])
    text = textwrap.fill(glued, width=width, initial_indent=" " * lead,
                         subsequent_indent=" " * (lead + 4), break_long_words=False,
                         break_on_hyphens=False)
    return text.replace("\u00a0", " ")

