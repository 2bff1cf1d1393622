"""Judges of the link (§6, L1-L10) and transport (§6.1-6.2, T1-T6) cases."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from itertools import pairwise

from eyeq_spi.catalog.link import link_spec
from eyeq_spi.conformance.judges.verdict import Context, Outcome, Span, at, bad, ok, skip, unsure
from eyeq_spi.conformance.model import TAG_CONTROL, TAG_GAP, TAG_LIMIT, TAG_SILENCE
from eyeq_spi.conformance.trace import Trace, Xfer
from eyeq_spi.link.frame import SEQ_MODULO, NakReason

_L = link_spec()
_T = _L["transport"]
W = int(_L["window"]["size"])
ACK_TIMEOUT = float(_L["timing"]["ackTimeout"])
TX_TIMEOUT = float(_L["timing"]["transmitTimeout"])
RESYNC_NAKS = int(_L["window"]["resync_after_naks"])
SINGLE, FIRST, CONSECUTIVE = (int(_T["types"][k]) for k in ("single", "first", "consecutive"))
ACK_SLACK_REALTIME = 0.002  # a byte stream between processes: delivery and our read turn
VERSIONS = 0x04  # the function of our transport probes: Get EyeQ Versions
RESET_SETTLE = 0.3  # seconds after a reset in which frames may be lost or NAKed 0x001


def _frame(xfer: Xfer) -> str:
    return f"frame #{xfer.index} ({xfer.direction}, {at(xfer.time)}, NUM {xfer.num})"


@dataclass
class Answer:
    frame: Xfer
    reply: Xfer | None


def answers(tr: Trace, slack: float) -> list[Answer]:
    """Pair each 128-byte non-control frame we sent with the DUT's ACK/NAK naming its NUM."""
    pending: dict[int, list[Xfer]] = {}
    out: dict[int, Answer] = {}
    limit = 5 * ACK_TIMEOUT + slack
    for xfer in tr.xfers:
        if xfer.direction == tr.our_dir and xfer.kind in ("DATA", "BAD"):
            pending.setdefault(xfer.num, []).append(xfer)
            out[xfer.index] = Answer(xfer, None)
        elif xfer.direction == tr.dut_dir and xfer.kind in ("ACK", "NAK"):
            queue = pending.get(xfer.rsp)
            while queue and (xfer.time - queue[0].time > limit or (
                    xfer.kind == "ACK" and (queue[0].kind == "BAD" or not queue[0].crc_ok))):
                queue.pop(0)  # too old, or a frame no receiver may ACK (bad CRC, D or R: L5)
            if queue:
                out[queue.pop(0).index].reply = xfer
    return list(out.values())


def _near_reset(tr: Trace, time: float) -> bool:
    return any(r - 0.05 <= time <= r + RESET_SETTLE for r in tr.resets())


def _nak_reason(xfer: Xfer | None) -> int | None:
    return xfer.num if xfer is not None and xfer.kind == "NAK" else None


# -- link -------------------------------------------------------------------------------------
def link_size(ctx: Context, tr: Trace) -> Outcome:
    dut = [xfer for xfer in tr.xfers if xfer.direction == tr.dut_dir]
    badlen = [xfer for xfer in dut if xfer.kind == "LEN"]
    if badlen:
        xfer = badlen[0]
        return bad(f"{len(badlen)} of {len(dut)} transfers are not 128 bytes; first: "
                   f"#{xfer.index} at {at(xfer.time)} is {len(xfer.data)} bytes")
    if not dut:
        return unsure("the DUT sent nothing")
    return ok(f"all {len(dut)} transfers from the DUT are 128 bytes")


def link_crc(ctx: Context, tr: Trace) -> Outcome:
    dut = [xfer for xfer in tr.xfers if xfer.direction == tr.dut_dir and xfer.kind != "LEN"]
    broken = [xfer for xfer in dut if not xfer.crc_ok or xfer.kind == "BAD"]
    if broken:
        xfer = broken[0]
        frame = tr.frames.decode(xfer.data)
        want = tr.frames.compute_crc(frame.d, xfer.data[:4], xfer.data[6:])
        return bad(f"{len(broken)} of {len(dut)} frames invalid; first: {_frame(xfer)} "
                   f"D=0x{frame.d:X} R=0x{frame.r:X} CRC 0x{frame.crc:04X}, expected 0x{want:04X}")
    return ok(f"{len(dut)} frames: CRC (L3 coverage), D and R valid")


def _since_restart(tr: Trace) -> Iterator[tuple[Xfer, int]]:
    """The DUT's DATA frames, each with the number of resets (L10) before it: a frame after a
    reset never repeats one before it, even byte for byte (a new boot status often is)."""
    restarts = sorted(tr.resets())
    count = 0
    for xfer in tr.xfers:
        if xfer.direction == tr.dut_dir and xfer.kind == "DATA":
            while count < len(restarts) and restarts[count] < xfer.time:
                count += 1
            yield xfer, count


def _repeats(tr: Trace) -> dict[int, Xfer]:
    """The DUT DATA frames (by index) that repeat an earlier one byte for byte within 1 s since
    the last restart, each with the frame it repeats (resends: judged by LINK-NORESEND alone)."""
    seen: dict[tuple[bytes, int], Xfer] = {}
    out: dict[int, Xfer] = {}
    for xfer, era in _since_restart(tr):
        prev = seen.get((xfer.data, era))
        if prev is not None and xfer.time - prev.time < 1.0:
            out[xfer.index] = prev
        seen[(xfer.data, era)] = xfer
    return out


def _dut_data(tr: Trace) -> Iterator[Xfer]:
    """The DUT's DATA frames in order, resends left out (:func:`_repeats`)."""
    repeats = _repeats(tr)
    return (x for x in tr.xfers
            if x.direction == tr.dut_dir and x.kind == "DATA" and x.index not in repeats)


RENUMBER_WITHIN = 1.0  # s after a reset the host asked for, to number from 0 again (L10)


def link_num(ctx: Context, tr: Trace) -> Outcome:
    """L4: +1 per DATA frame mod 4096, 0 after a reset. L10: a host that resets the EyeQ (a
    reset-line pulse, Switch EyeQ Application) numbers its frames from 0 again."""
    frames = list(_dut_data(tr))
    for earlier, xfer in pairwise(frames):
        if xfer.num not in ((earlier.num + 1) % SEQ_MODULO, 0):
            return bad(f"{_frame(xfer)}: expected NUM {(earlier.num + 1) % SEQ_MODULO} (or 0 "
                       f"after a reset), saw {xfer.num}")
    if not frames:
        return unsure("no DATA frames")
    restarts = 0
    if tr.dut == "host":
        data = [xfer for xfer in tr.xfers if xfer.direction == tr.dut_dir and xfer.kind == "DATA"]
        for mark in tr.marks:
            if mark.label not in ("reset_line", "soft_reset"):
                continue
            after = [xfer for xfer in data if mark.time < xfer.time <= mark.time + RENUMBER_WITHIN]
            if after and mark.time + RENUMBER_WITHIN <= tr.end \
                    and not any(xfer.num == 0 for xfer in after):
                return bad(f"the host reset us at {at(mark.time)} ({mark.label}); its {len(after)} "
                           f"DATA frames in the next {RENUMBER_WITHIN:.0f} s, from "
                           f"{_frame(after[0])}, never number from 0 again (L10: a reset "
                           "starts both link directions afresh)")
            restarts += bool(after)
    extra = f"; numbered from 0 again after each of {restarts} resets (L10)" if restarts else ""
    return ok(f"{len(frames)} DATA frames numbered +1 mod 4096{extra}")


def link_ack(ctx: Context, tr: Trace) -> Outcome:
    """L5, §6 ackTimeout: every DATA frame we sent is ACKed with RSP = its NUM within
    ackTimeout. From a reset to the first ACK LINK-RESYNC judges instead."""
    count = 0
    resets = sorted(tr.resets())
    resyncing_since: float | None = None
    # a byte stream adds far less to an ACK than the 50 ms other deadlines get (load.py)
    limit = ACK_TIMEOUT + (ACK_SLACK_REALTIME if ctx.realtime else 1e-6)
    late: list[tuple[Xfer, Xfer]] = []
    lost: list[Xfer] = []
    for answer in answers(tr, ctx.slack):
        xfer, reply = answer.frame, answer.reply
        while resets and resets[0] <= xfer.time:
            resyncing_since = resets.pop(0)
        if xfer.probe is not None or _near_reset(tr, xfer.time):
            continue
        if resyncing_since is not None:
            if reply is None or _nak_reason(reply) == NakReason.OUT_OF_WINDOW:
                continue
            resyncing_since = None
        if reply is None and xfer.time + 5 * ACK_TIMEOUT + ctx.slack > tr.end:
            continue  # sent as the session ended: its ACK had no time to come
        count += 1
        if reply is None:
            lost.append(xfer)
        elif reply.kind != "ACK" or reply.num != 0:
            return bad(f"{_frame(xfer)} answered by {reply.kind} #{reply.index} NUM/reason "
                       f"{reply.num}, expected an ACK with NUM 0")
        elif reply.time - xfer.time > limit:
            late.append((xfer, reply))
    if not count:
        return unsure("none of our frames could be judged")
    if lost or late:
        parts = []
        spans: list[Span] = []
        if lost:
            parts.append(f"{len(lost)} of {count} DATA frames never answered (no ACK with their "
                         f"NUM within {1e3 * 5 * ACK_TIMEOUT:.0f} ms), first {_frame(lost[0])}")
            spans += [(xfer.time, xfer.time + 5 * ACK_TIMEOUT, 4 * ACK_TIMEOUT) for xfer in lost]
        if late:
            worst = max(late, key=lambda p: p[1].time - p[0].time)
            frames = ", ".join(f"#{xfer.index}->#{reply.index} "
                               f"{1e3 * (reply.time - xfer.time):.2f} ms"
                               for xfer, reply in late[:5])
            parts.append(f"{len(late)} of {count} ACKs later than ackTimeout "
                         f"{1e3 * ACK_TIMEOUT:.0f} ms (§6, L7), worst "
                         f"{1e3 * (worst[1].time - worst[0].time):.2f} ms for {_frame(worst[0])}"
                         f"; first: {frames}")
            spans += [(xfer.time, reply.time, reply.time - xfer.time - ACK_TIMEOUT)
                      for xfer, reply in late]
        return bad("; ".join(parts), spans)
    return ok(f"{count} DATA frames ACKed with RSP = NUM within ackTimeout "
              f"{1e3 * ACK_TIMEOUT:.0f} ms")


def link_pad(ctx: Context, tr: Trace) -> Outcome:
    """§6 and L1: an ACK or NAK frame carries "122 pad bytes set to 0" (L3 lets a receiver
    ignore them, not a sender send others)."""
    ctl = [xfer for xfer in tr.xfers
           if xfer.direction == tr.dut_dir and xfer.kind in ("ACK", "NAK")]
    dirty = [xfer for xfer in ctl if any(xfer.data[6:])]
    if dirty:
        xfer = dirty[0]
        pos = next(i for i in range(6, len(xfer.data)) if xfer.data[i])
        return bad(f"{len(dirty)} of {len(ctl)} ACK/NAK frames have non-zero pad bytes; first: "
                   f"{xfer.kind} #{xfer.index} at {at(xfer.time)}, byte {pos} = "
                   f"0x{xfer.data[pos]:02X} (§6: 122 pad bytes set to 0)")
    kinds = {k: sum(1 for xfer in ctl if xfer.kind == k) for k in ("ACK", "NAK")}
    if not ctl:
        return skip("the DUT sent no ACK or NAK frame")
    return ok(f"{kinds['ACK']} ACK and {kinds['NAK']} NAK frames, every pad byte 0")


def _probe_nak(ctx: Context, tr: Trace, labels: tuple[str, ...], reason: NakReason) -> Outcome:
    found = [answer for answer in answers(tr, ctx.slack) if answer.frame.probe in labels]
    if not found:
        return skip("the probe was not sent (its step did not run)")
    parts = []
    for answer in found:
        got = _nak_reason(answer.reply)
        if got != int(reason) or answer.reply is None:
            reply = answer.reply
            seen = "nothing" if reply is None else \
                f"{reply.kind} #{reply.index} RSP {reply.rsp} NUM/reason 0x{reply.num:03X}"
            return bad(f"probe {answer.frame.probe} {_frame(answer.frame)}: expected NAK "
                       f"0x{reason:03X} with RSP {answer.frame.num}, saw {seen}")
        parts.append(f"{answer.frame.probe} #{answer.frame.index} -> NAK #{answer.reply.index}")
    return ok("; ".join(parts))


def nak_probe(reason: NakReason, *labels: str) -> Callable[[Context, Trace], Outcome]:
    """The judge of the probes ``labels``: each must be NAKed with ``reason`` (L5)."""
    return lambda ctx, tr: _probe_nak(ctx, tr, labels, reason)


def link_dup(ctx: Context, tr: Trace) -> Outcome:
    pair = [answer for answer in answers(tr, ctx.slack) if answer.frame.probe == "dup"]
    if not pair:
        return skip("the duplicate was not sent")
    answer = pair[0]
    if answer.reply is None or answer.reply.kind != "ACK":
        seen = "nothing" if answer.reply is None else f"{answer.reply.kind} #{answer.reply.index}"
        return bad(f"duplicate {_frame(answer.frame)}: expected an ACK with RSP {answer.frame.num} "
                   f"(L6), saw {seen}")
    mark = tr.first_mark("dup_request")
    if tr.dut == "host" or mark is None:
        return ok(f"duplicate {_frame(answer.frame)} ACKed again by #{answer.reply.index}; whether "
                  "the host dropped its payload is not observable on the link")
    replies = tr.replies(int(mark.info["tag"]), mark.info["function"], mark.time)
    if len(replies) != 1:
        return bad(f"duplicate {_frame(answer.frame)} ACKed, but the request was answered "
                   f"{len(replies)} times (expected once: the duplicate is dropped)")
    return ok(f"duplicate {_frame(answer.frame)} ACKed again by #{answer.reply.index} and dropped "
              f"(one reply, #{replies[0].indices[-1]})")


def link_resync(ctx: Context, tr: Trace) -> Outcome:
    mark = tr.first_mark("our_reset")
    if mark is None:
        return skip("our reset was not simulated")
    naks = 0
    first_ack: Xfer | None = None
    for answer in answers(tr, ctx.slack):
        if answer.frame.time < mark.time or answer.frame.probe is not None \
                or answer.reply is None:
            continue
        if answer.reply.kind == "ACK":
            first_ack = answer.reply
            break
        if _nak_reason(answer.reply) == NakReason.OUT_OF_WINDOW:
            naks += 1
        else:
            return bad(f"after our reset at {at(mark.time)}, {_frame(answer.frame)} got "
                       f"NAK 0x{answer.reply.num:03X} (only 0x001 is expected before resync)")
    if first_ack is None:
        return bad(f"after our reset at {at(mark.time)} none of our frames was ACKed again")
    if naks > RESYNC_NAKS:
        return bad(f"{naks} NAKs 0x001 before resynchronising (L6: at most {RESYNC_NAKS})")
    return ok(f"our reset at {at(mark.time)}: {naks} NAK(s) 0x001 (at most {RESYNC_NAKS}, L6), "
              f"then ACK #{first_ack.index} at {at(first_ack.time)}")


def link_noresend(ctx: Context, tr: Trace) -> Outcome:
    repeats = _repeats(tr)  # L10: never a repeat of a frame before a reset
    if repeats:
        index, prev = next(iter(repeats.items()))
        xfer = tr.xfers[index]
        return bad(f"{_frame(xfer)} repeats frame #{prev.index} byte for byte "
                   f"{1e3 * (xfer.time - prev.time):.1f} ms later: a resend (§6, L7)")
    count = sum(1 for _ in _since_restart(tr))
    if not count:
        return unsure("no DATA frames")
    unacked = _unacked(tr)
    if not unacked:
        return skip(f"all {count} DATA frames of the DUT were ACKed within ackTimeout: it never "
                    "had a frame to resend")
    return ok(f"{count} DATA frames, none resent: {unacked} of them were not ACKed within "
              "ackTimeout (our ACK blackout, our probes and resets, or lost on the link), each "
              "a frame the DUT might have resent, and it resent none (§6, L7)")


def _unacked(tr: Trace) -> int:
    """DUT DATA frames that no ACK of ours with their NUM followed within ackTimeout."""
    acks: dict[int, list[float]] = {}
    for xfer in tr.xfers:
        if xfer.direction == tr.our_dir and xfer.kind == "ACK":
            acks.setdefault(xfer.rsp, []).append(xfer.time)
    return sum(1 for xfer in tr.xfers if xfer.direction == tr.dut_dir and xfer.kind == "DATA"
               and not any(xfer.time <= t <= xfer.time + ACK_TIMEOUT
                           for t in acks.get(xfer.num, ())))


def link_window(ctx: Context, tr: Trace) -> Outcome:
    """L7: at most W DATA frames unacknowledged, counting only frames younger than ackTimeout
    (older ones are lost to the sender)."""
    outstanding: dict[int, float] = {}
    worst = 0
    repeats = _repeats(tr)
    for xfer in tr.xfers:
        if xfer.direction == tr.our_dir and xfer.kind in ("ACK", "NAK"):
            outstanding.pop(xfer.rsp, None)
        elif xfer.direction == tr.dut_dir and xfer.kind == "DATA" and xfer.index not in repeats:
            horizon = xfer.time - (ACK_TIMEOUT - 0.0005) + (0.0 if not ctx.realtime else 0.005)
            for num in [n for n, t in outstanding.items() if t <= horizon]:
                del outstanding[num]
            outstanding[xfer.num] = xfer.time
            worst = max(worst, len(outstanding))
            if len(outstanding) > W:
                # excess: how much older the frame that makes W + 1 had to be to leave the count
                times = sorted(outstanding.values())
                excess = times[len(times) - W - 1] - horizon
                return bad(f"{_frame(xfer)}: {len(outstanding)} DATA frames unacknowledged within "
                           f"ackTimeout (L7: at most {W})", [(times[0], xfer.time, excess)])
    blackout = tr.first_mark("ack_blackout")
    note = f" (ACK blackout at {at(blackout.time)})" if blackout else ""
    if worst < W:
        # the limit was never reached: whether the DUT would stop at W is unknown
        return skip(f"the DUT never had W = {W} DATA frames unacknowledged (at most {worst}"
                    f"{note}): the window limit was not exercised")
    return ok(f"at most {worst} DATA frames unacknowledged{note}")


def _transfers(tr: Trace) -> list[list[Xfer]]:
    """The frames seen of each multi-frame transfer the DUT sent."""
    out: list[list[Xfer]] = []
    for xfer in tr.xfers:
        if xfer.direction != tr.dut_dir or xfer.kind != "DATA":
            continue
        if xfer.ttype == FIRST:
            out.append([xfer])
        elif xfer.ttype == CONSECUTIVE and out and xfer.data[7] == out[-1][0].data[7]:
            out[-1].append(xfer)
    return out


def link_txtimeout(ctx: Context, tr: Trace) -> Outcome:
    slack = 0.001 if not ctx.realtime else 0.010
    ts = _transfers(tr)
    for frames in ts:
        first, last = frames[0], frames[-1]
        if last.time - first.time > TX_TIMEOUT + slack:
            excess = last.time - first.time - TX_TIMEOUT
            return bad(f"transfer ID {first.data[7]}: first frame #{first.index} at "
                       f"{at(first.time)}, frame {len(frames)} #{last.index} at {at(last.time)}: "
                       f"{1e3 * (last.time - first.time):.1f} ms > transmitTimeout "
                       f"{1e3 * TX_TIMEOUT:.0f} ms", [(first.time, last.time, excess)])
    if not ts:
        return skip("the DUT sent no multi-frame transfer: every message fitted one frame")
    worst = max(frames[-1].time - frames[0].time for frames in ts)
    return ok(f"{len(ts)} multi-frame transfers, longest {1e3 * worst:.2f} ms "
              f"(transmitTimeout {1e3 * TX_TIMEOUT:.0f} ms)")


def link_gap(ctx: Context, tr: Trace) -> Outcome:
    if not ctx.realtime:
        return skip("judged on real time only (virtual time proves nothing about the wire)")
    gap = float(_L["timing"]["frameFlowControl"][tr.dut])
    # frames the DUT had queued together: those of its multi-frame transfers
    data = [x for frames in _transfers(tr) for x in tr.xfers[frames[0].index:frames[-1].index + 1]
            if x.direction == tr.dut_dir and x.kind == "DATA"]
    span = 50  # a byte stream may deliver frames in bursts: judge the spacing of 50 frames
    if len(data) <= span:
        return skip(f"the DUT sent {len(data)} DATA frames in multi-frame transfers (need "
                    f"{span + 1}): it never had frames queued back to back")
    worst = min(range(len(data) - span), key=lambda i: data[i + span].time - data[i].time)
    mean = (data[worst + span].time - data[worst].time) / span
    if mean < 0.5 * gap:
        return bad(f"frames #{data[worst].index}..#{data[worst + span].index}: mean gap "
                   f"{1e6 * mean:.0f} µs < frameFlowControl {1e6 * gap:.0f} µs",
                   [(data[worst].time, data[worst + span].time,
                     span * (0.5 * gap - mean))])
    return ok(f"{len(data)} DATA frames; tightest 50-frame mean gap {1e6 * mean:.0f} µs "
              f">= half of {1e6 * gap:.0f} µs (receive times over a byte stream bunch)")


# -- transport --------------------------------------------------------------------------------
def tp_format(ctx: Context, tr: Trace) -> Outcome:
    limit = int(_T["receive_limit"]["host" if tr.dut == "eyeq" else "eyeq"])
    open_id: int | None = None
    interloper: Xfer | None = None
    frames = list(_dut_data(tr))
    for xfer in frames:
        data, ttype = xfer.data, xfer.ttype
        if ttype == SINGLE:
            size = data[7]
            if not 1 <= size <= _T["single_max"] or any(data[8 + size:]):
                return bad(f"{_frame(xfer)}: single frame size {size}, pad not zero or size out "
                           "of 1..120 (T2)")
            if open_id is not None:
                interloper = xfer
        elif ttype == FIRST:
            total = int.from_bytes(data[8:12], "little")
            if not _T["first_total_min"] <= total <= limit:
                return bad(f"{_frame(xfer)}: first frame total {total} outside "
                           f"{_T['first_total_min']}..{limit} (T3)")
            open_id, interloper = data[7], None
        elif ttype == CONSECUTIVE:
            if open_id is None or data[7] != open_id:
                return bad(f"{_frame(xfer)}: consecutive frame ID {data[7]}, open transfer "
                           f"{open_id} (T4)")
            if interloper is not None:
                return bad(f"{_frame(xfer)} continues transfer {open_id} after "
                           f"frame #{interloper.index} interleaved (T5)")
        else:
            return bad(f"{_frame(xfer)}: transport type 0x{ttype:02X} (T1)")
    return ok(f"{len(frames)} DATA frames with valid single/first/consecutive headers") \
        if frames else unsure("no DATA frames")


def tp_tid(ctx: Context, tr: Trace) -> Outcome:
    firsts = [x for x in tr.xfers if x.direction == tr.dut_dir and x.kind == "DATA"
              and x.ttype == FIRST]
    if len(firsts) < 2:
        return unsure(f"{len(firsts)} multi-frame transfers: nothing to compare")
    restarts = tr.restarts(tr.dut_dir)
    skips = 0
    for earlier, later in pairwise(firsts):
        if any(earlier.time < r <= later.time for r in restarts):
            continue
        step = (later.data[7] - earlier.data[7]) % _T["transfer_id_modulo"]
        # a message lost before its first frame left consumed its ID (L7): a step of a few is
        # allowed where the link was disturbed, never 0 or backwards
        lost_ok = tr.disturbed(earlier.time, later.time) or tr.realtime
        if step != 1 and not (lost_ok and 1 < step <= 2 * W):
            return bad(f"transfer ID {earlier.data[7]} (#{earlier.index}) then {later.data[7]} "
                       f"(#{later.index}): expected +1 (T3)")
        skips += step != 1
    extra = f" ({skips} steps over IDs of messages lost on a disturbed link)" if skips else ""
    return ok(f"{len(firsts)} transfer IDs, each +1 mod 256{extra}")


def _answered(tr: Trace, tag: int, since: float) -> bool:
    """A reply with ``ret`` to our Get EyeQ Versions probe ``tag`` came within 1 s."""
    return any(len(msg.data) >= 9 for msg in tr.replies(tag, VERSIONS, since))


def tp_limit(ctx: Context, tr: Trace) -> Outcome:
    base = _probe_nak(ctx, tr, ("limit_over#0",), NakReason.FORMAT_ERROR)
    if base.verdict != "pass" or tr.dut == "host":
        return base
    at_limit = tr.first_mark("limit_at")
    if at_limit is None:
        return base
    if not _answered(tr, TAG_LIMIT, at_limit.time):
        return bad(f"{base.evidence}; but the {_T['receive_limit']['eyeq']}-byte request sent "
                   f"at {at(at_limit.time)} was never answered (the limit itself must pass)")
    return ok(f"{base.evidence}; a message of exactly the limit was reassembled and answered")


def tp_abort(ctx: Context, tr: Trace) -> Outcome:
    marks = {mark.label: mark for mark in tr.marks if mark.label.startswith("abort_")}
    if "abort_control" not in marks:
        return skip("the transport probes were not sent")
    if not _answered(tr, TAG_CONTROL, marks["abort_control"].time):
        return unsure("the complete 300-byte control request got no reply either")
    for label, tag in (("abort_gap", TAG_GAP), ("abort_silence", TAG_SILENCE)):
        mark = marks.get(label)
        if mark is not None and _answered(tr, tag, mark.time):
            why = "a NUM gap" if label == "abort_gap" else "25 ms of silence"
            return bad(f"the request broken by {why} at {at(mark.time)} was answered: the "
                       "transfer was not aborted (T6)")
    return ok("control request answered; the one with a NUM gap and the one with 40 ms of "
              "silence were aborted (no reply)")
