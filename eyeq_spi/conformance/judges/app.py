"""Judges of the MESP (§7.1.1, M1-M6) and DASP (§7.1.2, §7.1.4-7.1.5, D1-D5) cases."""

from __future__ import annotations

import bisect
from collections.abc import Callable
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

from eyeq_spi.catalog.messages import MessageDef, catalog
from eyeq_spi.codec.intrinsic import eeprom_crc_ok
from eyeq_spi.codec.layout import Layout
from eyeq_spi.conformance.judges.link import answers
from eyeq_spi.conformance.judges.verdict import Context, Outcome, at, bad, ok, skip, unsure
from eyeq_spi.conformance.model import (
    PROBE_CASE,
    TAG_EARLY_INIT,
    TAG_GAP,
    TAG_LIMIT,
    TAG_SILENCE,
)
from eyeq_spi.conformance.trace import Msg, Trace
from eyeq_spi.stream_rate import combined_rate, stream_rate

_M = catalog().raw["mesp.yaml"]["mesp"]
DEADLINE = float(_M["reply_deadline"])
RET_UNKNOWN = 2
MODE_OF_MAIN = {0x02: "APP", 0xAC: "TAC", 0x22: "SPC"}
RATE_MEAN_TOLERANCE = 0.05  # our reading: the tolerance bounds each period, the rate the mean


def ret_of(msg: Msg) -> int | None:
    return int.from_bytes(msg.data[5:9], "little") if len(msg.data) >= 9 else None


def is_request(msg: Msg) -> bool:
    return msg.decoded.protocol == "MESP" and not msg.header.get("reply")


def is_reply(msg: Msg) -> bool:
    return msg.decoded.protocol == "MESP" and bool(msg.header.get("reply"))


@dataclass
class Pair:
    request: Msg
    reply: Msg | None


def mesp_pairs(tr: Trace, *, dut_asks: bool = False) -> list[Pair]:
    """Requests we sent (the DUT sent, with ``dut_asks``) paired with the other side's replies
    by service and function, in order, so that a reply with a wrong tag is still found (and
    judged by the tag case alone)."""
    asking, answering = (tr.dut_msgs, tr.our_msgs) if dut_asks else (tr.our_msgs, tr.dut_msgs)
    pairs = [Pair(m, None) for m in asking() if is_request(m)]
    for rep in answering():
        if not is_reply(rep):
            continue
        key = (rep.header["service"], rep.header["function"])
        open_ = [p for p in pairs if p.reply is None and p.request.time <= rep.time
                 and (p.request.header["service"], p.request.header["function"]) == key]
        if not open_:
            continue
        # the request with the reply's counter, else the oldest open one (a wrong tag)
        counter = rep.header["tag"] & 0x3F
        same = [p for p in open_ if p.request.header["tag"] & 0x3F == counter]
        (same[-1] if same else open_[0]).reply = rep
    return pairs


def delivered(tr: Trace, ctx: Context) -> set[int]:
    """Trace indices of our frames the DUT ACKed."""
    return {a.frame.index for a in answers(tr, ctx.slack)
            if a.reply is not None and a.reply.kind == "ACK"}


# -- MESP, the EyeQ as server -----------------------------------------------------------------
def _reply_ok(fn: str, req: dict[str, Any], rep: dict[str, Any]) -> str | None:
    """None if the reply parameters are right for the request (M3), else what is wrong."""
    echo = {"SwitchEyeQApplication": ("applicationId",),
            "SendParamsToCalibrationTool": ("edr_type", "edr_policy", "edr_function"),
            "EventCalibrationTool": ("ct_type", "ct_stage", "ct_version"),
            "ComputeHash": ("hashType", "datasetType")}.get(fn, ())
    for key in echo:
        if rep.get(key) != req.get(key):
            return f"{key} {rep.get(key)!r}, request had {req.get(key)!r}"
    if fn == "ComputeHash":
        want = 4 if req.get("hashType") == 1 else 32
        if len(rep.get("result", b"")) != want:
            return f"result is {len(rep.get('result', b''))} bytes, expected {want}"
    if fn == "FFSReadFile" and req.get("filename") == "/mesp/eeprom.data1" \
            and not eeprom_crc_ok(bytes(rep.get("data", b""))):
        return "the EEPROM image's CRC-16 (bytes 0x4C..0x4D, I2) does not match"
    return None


def mesp_function(fn: str) -> Callable[[Context, Trace], Outcome]:
    def judge(ctx: Context, tr: Trace) -> Outcome:
        pairs = [pair for pair in mesp_pairs(tr) if pair.request.name == fn]
        if not pairs:
            return unsure(f"no {fn} request was made in this run")
        good = []
        for pair in pairs:
            reply = pair.reply
            if reply is None or ret_of(reply) != 0:
                continue
            if reply.decoded.errors:
                return bad(f"reply #{reply.indices[-1]} at {at(reply.time)}: "
                           f"{reply.decoded.errors[0]}")
            wrong = _reply_ok(fn, pair.request.fields, reply.fields)
            if wrong is not None:
                return bad(f"reply #{reply.indices[-1]} at {at(reply.time)}: {wrong}")
            good.append(reply)
        if not good:
            rets = [ret_of(pair.reply) if pair.reply else None for pair in pairs]
            return bad(f"{len(pairs)} request(s), no successful reply (ret seen: {rets})")
        others = _not_counted(ctx, tr, [pair for pair in pairs if pair.reply not in good])
        return ok(f"{len(good)} of {len(pairs)} request(s) answered with ret 0 and correct "
                  f"parameters; first reply #{good[0].indices[-1]} at {at(good[0].time)}"
                  + (f"; the other {len(pairs) - len(good)}: {others}" if others else ""))
    return judge


def _not_counted(ctx: Context, tr: Trace, pairs: list[Pair]) -> str:
    """Why requests of a passing function case did not count."""
    acked = delivered(tr, ctx)
    probes: dict[str, int] = {}
    lost = refused = unanswered = 0
    rets: list[int] = []
    for pair in pairs:
        req, rep = pair.request, pair.reply
        case = PROBE_CASE.get((int(req.header["counter"]), req.name))
        if case is not None:
            probes[case] = probes.get(case, 0) + 1
        elif not all(i in acked for i in req.indices):
            lost += 1
        elif rep is None:
            unanswered += 1
        else:
            refused += 1
            rets.append(ret_of(rep) or 0)
    parts = [f"{n} of our probe requests, judged by {case}" for case, n in probes.items()]
    if lost:
        parts.append(f"{lost} lost on the link (not ACKed: around our faults or resets)")
    if refused:
        parts.append(f"{refused} refused in the EyeQ's state of the moment (ret "
                     f"{', '.join(map(str, sorted(set(rets))))}), as M2 allows")
    if unanswered:
        parts.append(f"{unanswered} unanswered, judged by MESP-DEADLINE")
    return "; ".join(parts)


def mesp_tag(ctx: Context, tr: Trace) -> Outcome:
    answered = [(pair.request, pair.reply) for pair in mesp_pairs(tr) if pair.reply is not None]
    for request, reply in answered:
        want = 0x80 | (request.header["tag"] & 0x3F)
        got = reply.header["tag"]
        if got != want:
            return bad(f"{request.name} request tag 0x{request.header['tag']:02X} "
                       f"(#{request.indices[0]}): reply #{reply.indices[-1]} tag "
                       f"0x{got:02X}, expected 0x{want:02X} (M1)")
    if not answered:
        return unsure("no replies")
    return ok(f"{len(answered)} replies echo service, function and tag counter with bit 7 set")


def mesp_deadline(ctx: Context, tr: Trace) -> Outcome:
    acked = delivered(tr, ctx)
    skip_tags = {TAG_EARLY_INIT, TAG_GAP, TAG_SILENCE, TAG_LIMIT}
    worst = 0.0
    count = 0
    for pair in mesp_pairs(tr):
        req = pair.request
        if req.header["counter"] in skip_tags and req.name in (
                "GetEyeQVersions", "EventCalibrationTool"):
            continue
        if not all(i in acked for i in req.indices) or tr.end - req.time < DEADLINE:
            continue
        count += 1
        if pair.reply is None:
            return bad(f"{req.name} request #{req.indices[0]} at {at(req.time)} never answered",
                       [(req.time, tr.end, max(tr.end - req.time - DEADLINE, DEADLINE))])
        dt = pair.reply.time - req.time
        worst = max(worst, dt)
        if dt > DEADLINE + ctx.slack:
            return bad(f"{req.name} request #{req.indices[0]} at {at(req.time)}: reply "
                       f"#{pair.reply.indices[-1]} after {1e3 * dt:.1f} ms (> 500 ms, §7.1.1, M6)",
                       [(req.time, pair.reply.time, dt - DEADLINE)])
    if not count:
        return unsure("no delivered requests")
    return ok(f"{count} delivered requests answered, slowest in {1e3 * worst:.2f} ms")


def _probe_replies(tr: Trace, label: str) -> list[tuple[Any, int | None]]:
    """Each probe ``label`` with the ``ret`` of its first reply (None: no reply)."""
    out: list[tuple[Any, int | None]] = []
    for mark in tr.marks_of(label):
        replies = tr.replies(mark.info["tag"], mark.info["function"], mark.time)
        out.append((mark, ret_of(replies[0]) if replies else None))
    return out


def mesp_bad_params(ctx: Context, tr: Trace) -> Outcome:
    res = _probe_replies(tr, "bad_params")
    if not res:
        return skip("not probed")
    for mark, ret in res:
        if ret is None or ret == 0:
            return bad(f"request with bad parameters at {at(mark.time)} (function "
                       f"0x{mark.info['function']:02X}): {'no reply' if ret is None else 'ret 0'}"
                       ", expected ret != 0 (M2)")
    return ok("; ".join(f"function 0x{m.info['function']:02X} -> ret {r}" for m, r in res))


def mesp_unknown(ctx: Context, tr: Trace) -> Outcome:
    res = _probe_replies(tr, "unknown_function") + _probe_replies(tr, "unknown_service")
    if not res:
        return skip("not probed")
    for mark, ret in res:
        if ret != RET_UNKNOWN:
            return bad(f"unknown 0x{mark.info['service']:02X}/0x{mark.info['function']:02X} at "
                       f"{at(mark.time)}: {'no reply' if ret is None else f'ret {ret}'}, "
                       "expected ret 2 (M2)")
    return ok("; ".join(f"0x{m.info['service']:02X}/0x{m.info['function']:02X} -> ret {r}"
                        for m, r in res))


# -- MESP, the host as client -----------------------------------------------------------------
def mesp_request_tags(ctx: Context, tr: Trace) -> Outcome:
    last: int | None = None
    reqs = [msg for msg in tr.dut_msgs() if is_request(msg)]
    for msg in reqs:
        tag = msg.header["tag"]
        if tag & 0xC0:
            return bad(f"request #{msg.indices[0]} tag 0x{tag:02X}: bits 6 and 7 must be 0 (M1)")
        if last is not None and tag != (last + 1) & 0x3F:
            return bad(f"request #{msg.indices[0]} at {at(msg.time)}: tag counter {tag}, expected "
                       f"{(last + 1) & 0x3F} (+1 per request, M1)")
        last = tag
    return ok(f"{len(reqs)} requests, tag counter +1 each") if reqs else unsure("no requests")


def mesp_unmatched(ctx: Context, tr: Trace) -> Outcome:
    mark = tr.first_mark("unmatched_reply")
    if mark is None:
        return skip("no unmatched reply was sent")
    pending = [m for m in tr.our_msgs("EYEQ_DIAGNOSTIC_MSG") if m.fields.get("Main_State") == 1]
    t_pending = pending[0].time if pending else tr.end
    early = [m for m in tr.dut_msgs("EventCalibrationTool") if is_request(m)
             and mark.time <= m.time < t_pending]
    if early:
        return bad(f"an unmatched reply (tag {mark.info['tag']}) claiming Pending Vision at "
                   f"{at(mark.time)} was taken: init request #{early[0].indices[0]} at "
                   f"{at(early[0].time)} before we reported Pending at {at(t_pending)}")
    return ok(f"unmatched reply at {at(mark.time)} ignored; first init request only after "
              f"Pending Vision at {at(t_pending)}")


# -- DASP --------------------------------------------------------------------------------------
def _mode_at(tr: Trace) -> Callable[[float], str | None]:
    """The DUT's mode at a time, from its 0x41 Main_State: only where the report before and the
    report after agree (a message sent during a switch belongs to neither mode)."""
    if tr.dut == "host":
        return lambda t: "APP"
    diag = [(m.time, MODE_OF_MAIN.get(int(m.fields.get("Main_State", -1))))
            for m in tr.dut_msgs("EYEQ_DIAGNOSTIC_MSG") if m.fields]
    times = [t for t, _ in diag]

    def mode(time: float) -> str | None:
        index = bisect.bisect_right(times, time)
        if index == 0 or index == len(diag):
            return None
        before, after = diag[index - 1][1], diag[index][1]
        return before if before == after else None
    return mode


def dasp_msgs(tr: Trace) -> list[Msg]:
    return [m for m in tr.dut_msgs() if m.decoded.protocol == "DASP"]


def _defs(tr: Trace) -> dict[str, MessageDef]:
    return {m.name: m for m in tr.codec.cat.messages if m.protocol == "DASP"
            and m.exists_in(tr.codec.sw)}


def bring_ups(tr: Trace) -> list[float]:
    """When the implementation under test started its application again (an EyeQ's boot
    status, a host's 0x92): its counters may start afresh there."""
    if tr.dut == "eyeq":
        return [m.time for m in tr.dut_msgs("EYEQ_BOOT_STATUS_MSG")]
    return [m.time for m in tr.dut_msgs("EventCalibrationTool")
            if is_request(m) and m.fields.get("ct_stage") == 0x92]


def segments(tr: Trace, msgs: list[Msg], period: float, *, lossless: bool = False
             ) -> list[list[Msg]]:
    """Runs of one stream without a gap of 3 periods, a fault window, a reset or a mode
    change in between: the spans in which counters and rates must hold. ``lossless``
    (counters): a stall of ours also ends a run, since our late ACKs may have lost a message."""
    mode = _mode_at(tr)
    resets = tr.resets() + bring_ups(tr)
    out: list[list[Msg]] = []
    cur: list[Msg] = []
    for msg in msgs:
        if cur:
            last = cur[-1]
            if (msg.t_first - last.t_first > 3 * period or tr.disturbed(last.t_first, msg.time)
                    or (lossless and tr.stalled(last.t_first, msg.time))
                    or any(last.t_first <= r <= msg.t_first for r in resets)
                    or mode(last.t_first) != mode(msg.t_first)):
                out.append(cur)
                cur = []
        cur.append(msg)
    if cur:
        out.append(cur)
    return out


def dasp_counter(ctx: Context, tr: Trace) -> Outcome:
    msgs = dasp_msgs(tr)
    by_id: dict[int, list[Msg]] = {}
    for msg in msgs:
        by_id.setdefault(int(msg.header["data_id"]), []).append(msg)
    for did, ms in by_id.items():
        for seg in segments(tr, ms, 1.0, lossless=True):
            for earlier, later in pairwise(seg):
                if later.header["counter"] != (earlier.header["counter"] + 1) & 0xFF:
                    return bad(f"data ID 0x{did:02X}: counter {earlier.header['counter']} "
                               f"(#{earlier.indices[0]}) then {later.header['counter']} "
                               f"(#{later.indices[0]}, {at(later.time)}), expected +1 (D1)")
    ids = f"{len(by_id)} data ID{'' if len(by_id) == 1 else 's'}"
    return ok(f"{len(msgs)} DASP messages, {ids}, counters +1") if msgs else \
        unsure("no DASP messages")


def dasp_length(ctx: Context, tr: Trace) -> Outcome:
    msgs = dasp_msgs(tr)
    for msg in msgs:
        hdr = [e for e in msg.decoded.errors if e.startswith("BadHdr")]
        if hdr:
            return bad(f"message #{msg.indices[0]} at {at(msg.time)}: {hdr[0]} (D3)")
    return ok(f"{len(msgs)} DASP messages, payload lengths of {tr.codec.sw}") if msgs else \
        unsure("no DASP messages")


def dasp_e2e(ctx: Context, tr: Trace) -> Outcome:
    msgs = dasp_msgs(tr)
    checked = 0
    streams: dict[str, list[Msg]] = {}
    for msg in msgs:
        crc = [e for e in msg.decoded.errors if e.startswith("E2E")]
        if crc:
            return bad(f"{msg.name} #{msg.indices[0]} at {at(msg.time)}: {crc[0]} (D5)")
        streams.setdefault(msg.name, []).append(msg)
    defs = _defs(tr)
    for name, ms in streams.items():
        definition = defs.get(name)
        if definition is None:
            continue
        lay = tr.codec.layout(definition)
        plans = [plan for plan in lay.crc_plan if plan.counter_offset is not None]
        if not plans:
            continue
        for seg in segments(tr, ms, 1.0, lossless=True):
            for earlier, later in pairwise(seg):
                for plan in plans:
                    offset, size = 4 + int(plan.counter_offset or 0), plan.counter_size
                    va = int.from_bytes(earlier.data[offset:offset + size], "little")
                    vb = int.from_bytes(later.data[offset:offset + size], "little")
                    checked += 1
                    if vb != (va + 1) % (1 << (8 * size)):
                        return bad(f"{name}.{plan.path or plan.field}: rollingFrameCount {va} "
                                   f"(#{earlier.indices[0]}) then {vb} (#{later.indices[0]}, "
                                   f"{at(later.time)}), expected +1 (D5)")
    if not msgs:
        return unsure("no DASP messages")
    return ok(f"{len(msgs)} DASP messages: every crc_16 right, {checked} rollingFrameCount steps")


def unused_masks(lay: Layout, base: int = 0) -> list[tuple[int, int, int]]:
    """(absolute offset, size, mask of unused bits) of every bitfield container (D2)."""
    out: list[tuple[int, int, int]] = []
    used: dict[int, tuple[int, int]] = {}
    for info in lay.fields:
        if info.bits is not None:
            lo, hi = info.bits
            mask = ((1 << (hi - lo + 1)) - 1) << lo
            size, prev = used.get(info.offset, (info.size, 0))
            used[info.offset] = (size, prev | mask)
        child = lay.children.get(info.name)
        if child is not None:
            for element in range(info.count or 1):
                out += unused_masks(child, base + info.offset + element * child.size)
    for off, (size, mask) in used.items():
        unused = ((1 << (8 * size)) - 1) & ~mask
        if unused:
            out.append((base + off, size, unused))
    return out


def dasp_unused(ctx: Context, tr: Trace) -> Outcome:
    defs = _defs(tr)
    sampled: dict[str, int] = {}
    containers = 0
    for msg in dasp_msgs(tr):
        definition = defs.get(msg.name)
        # an E2E error (D5, judged by DASP-E2E) leaves the bitfields readable: judge them too
        broken = [e for e in msg.decoded.errors if not e.startswith("E2E ")]
        if definition is None or sampled.get(msg.name, 0) >= 3 or broken:
            continue
        sampled[msg.name] = sampled.get(msg.name, 0) + 1
        for off, size, mask in unused_masks(tr.codec.layout(definition)):
            containers += 1
            value = int.from_bytes(msg.data[4 + off:4 + off + size], "little")
            if value & mask != mask:
                return bad(f"{msg.name} #{msg.indices[0]}: container at payload byte {off} is "
                           f"0x{value:0{2 * size}X}, unused bits 0x{mask:0{2 * size}X} must be 1 "
                           "(§7.1.2, D2)")
    if not sampled:
        return unsure("no DASP messages")
    return ok(f"{containers} bitfield containers in {sum(sampled.values())} messages of "
              f"{len(sampled)} kind{'' if len(sampled) == 1 else 's'}: unused bits all 1")


def _rate(ctx: Context, tr: Trace, msgs: list[Msg], hz: float, tol: tuple[float, float],
          what: str) -> Outcome:
    period = 1.0 / hz
    lo, hi = period + tol[0] / 1e3, period + tol[1] / 1e3
    slack = 0.002 if ctx.realtime else 1e-9
    periods: list[tuple[float, Msg]] = []
    rates = []
    for seg in segments(tr, msgs, period):
        rates.append(stream_rate([m.t_first for m in seg]))
        for earlier, later in pairwise(seg):
            periods.append((later.t_first - earlier.t_first, later))
    if len(periods) < 5:
        return unsure(f"{len(periods)} periods of {what} observed (need 5)")
    outside = [(p, msg) for p, msg in periods if not lo - slack <= p <= hi + slack]
    # the stream's rate while it runs (eyeq_spi/stream_rate.py); a gap is judged as a period
    running = combined_rate(rates)
    mean = 1.0 / running if running else sum(p for p, _ in periods) / len(periods)
    # each violation with its span and excess (load.py): a period outside the tolerance, and
    # the mean rate, whose excess is how far the whole run is off the nearest rate allowed
    spans = [(msg.t_first - p, msg.t_first, (lo - p) if p < lo else (p - hi)) for p, msg in outside]
    fast, slow = 1.0 / ((1 + RATE_MEAN_TOLERANCE) * hz), 1.0 / ((1 - RATE_MEAN_TOLERANCE) * hz)
    mean_off = abs(1.0 / mean - hz) > RATE_MEAN_TOLERANCE * hz
    if mean_off:
        t0 = min(msg.t_first - p for p, msg in periods)
        t1 = max(msg.t_first for _, msg in periods)
        total = sum(p for p, _ in periods)
        spans.append((t0, t1, max(total - len(periods) * slow, len(periods) * fast - total)))
    if outside:
        spacing, msg = outside[0]
        return bad(f"{what}: {len(outside)} of {len(periods)} periods outside "
                   f"{1e3 * lo:.1f}..{1e3 * hi:.1f} ms, first {1e3 * spacing:.2f} ms before "
                   f"#{msg.indices[0]} at {at(msg.t_first)}; mean rate {1 / mean:.2f} Hz", spans)
    if mean_off:
        return bad(f"{what}: mean rate {1 / mean:.2f} Hz over {len(periods)} periods, "
                   f"nominal {hz} Hz (±{100 * RATE_MEAN_TOLERANCE:.0f} %)", spans)
    return ok(f"{what}: {len(periods)} periods {1e3 * min(p for p, _ in periods):.2f}.."
              f"{1e3 * max(p for p, _ in periods):.2f} ms, mean {1 / mean:.2f} Hz")


def dasp_rate(name: str, mode: str | None = None) -> Callable[[Context, Trace], Outcome]:
    """The rate of ``name`` while the DUT is in ``mode`` (None: always)."""
    def judge(ctx: Context, tr: Trace) -> Outcome:
        definition = tr.codec.cat.message(name)
        if definition.rate_hz is None or definition.tolerance_ms is None:
            return skip(f"{name} has no periodic rate")
        at_mode = _mode_at(tr)
        msgs = [m for m in tr.dut_msgs(name) if mode is None or at_mode(m.t_first) == mode]
        return _rate(ctx, tr, msgs, float(definition.rate_hz), definition.tolerance_ms,
                     name if mode is None else f"{name} in {mode}")
    return judge
