"""Judges of the flow cases (MAPC-67299 message flow, §7.1.3 intrinsic calibration, mode
switches) and of the host-under-test reactions to the faults we inject."""

from __future__ import annotations

from collections.abc import Callable

from eyeq_spi.catalog.bringup import EEPROM_FILE, FATAL_INTRINSIC
from eyeq_spi.conformance.judges.app import DEADLINE, is_reply, is_request, mesp_pairs, ret_of
from eyeq_spi.conformance.judges.verdict import Context, Outcome, advise, at, bad, ok, skip, unsure
from eyeq_spi.conformance.trace import Msg, Trace

PENDING, RUNNING_VISION, PENDING_VISION = 0x01, 0x02, 0x92


def _state_reports(tr: Trace) -> list[tuple[float, int, int, int, Msg]]:
    """(time, mainState, subState, Fatal_Error) from the DUT's 0x41 and Get Extended State
    replies."""
    out = []
    for msg in tr.dut_msgs():
        if msg.name == "EYEQ_DIAGNOSTIC_MSG" and msg.fields:
            fields = msg.fields
            out.append((msg.time, int(fields["Main_State"]), int(fields["Sub_State"]),
                        int(fields["Fatal_Error"]), msg))
        elif (msg.name == "GetEyeQExtendedState" and is_reply(msg) and ret_of(msg) == 0
              and msg.fields):
            fields = msg.fields
            out.append((msg.time, int(fields["mainState"]), int(fields["subState"]), 0, msg))
    return out


def _ect_replies(tr: Trace, stage: int | None = None, *, dut_asks: bool = False
                 ) -> list[tuple[Msg, Msg]]:
    return [(pair.request, pair.reply) for pair in mesp_pairs(tr, dut_asks=dut_asks)
            if pair.request.name == "EventCalibrationTool" and pair.reply is not None
            and (stage is None or pair.request.fields.get("ct_stage") == stage)]


# -- the EyeQ under test ----------------------------------------------------------------------
def boot_first(ctx: Context, tr: Trace) -> Outcome:
    msgs = tr.dut_msgs()
    if not msgs:
        return bad("the DUT sent no message")
    first = msgs[0]
    if first.name != "EYEQ_BOOT_STATUS_MSG":
        return bad(f"first message #{first.indices[0]} at {at(first.time)} is {first.name}, "
                   "expected EYEQ_BOOT_STATUS_MSG (0x10)")
    return ok(f"EYEQ_BOOT_STATUS_MSG first, #{first.indices[0]} at {at(first.time)}")


def pending_before_init(ctx: Context, tr: Trace) -> Outcome:
    reports = _state_reports(tr)
    pending = [r for r in reports if r[1] == PENDING and r[2] == PENDING_VISION]
    t_pending = pending[0][0] if pending else None
    for req, rep in _ect_replies(tr):
        if ret_of(rep) != 0:
            continue
        if t_pending is None or rep.time < t_pending:
            stage = req.fields.get("ct_stage", 0)
            when = "never" if t_pending is None else at(t_pending)
            return bad(f"init 0x{stage:02X} (request #{req.indices[0]}) accepted with ret 0 at "
                       f"{at(rep.time)}, but Pending Vision was reported {when}")
    if t_pending is None:
        return unsure("the DUT never reported Pending Vision")
    early = tr.first_mark("early_init")
    extra = f"; the 0x92 sent at {at(early.time)} while booting was refused" if early else ""
    return ok(f"Pending Vision reported at {at(t_pending)}, no init accepted before{extra}")


def running_after_init(ctx: Context, tr: Trace) -> Outcome:
    reports = _state_reports(tr)
    running = [r for r in reports if r[1] == RUNNING_VISION]
    if not running:
        return unsure("the DUT never reported Running Vision")
    t_run, src = running[0][0], running[0][4]
    accepted = [rep for _, rep in _ect_replies(tr, 0x92) if ret_of(rep) == 0
                and rep.time <= t_run]
    if not accepted:
        return bad(f"Running Vision at {at(t_run)} (#{src.indices[0]}) without an accepted "
                   "Init_Params_Vision (0x92)")
    t92 = accepted[-1].time
    veh = [m for m in tr.our_msgs("HOST_VEH_STATE_MSG") if t92 <= m.time <= t_run]
    if not veh:
        return bad(f"Running Vision at {at(t_run)} (#{src.indices[0]}): 0x92 accepted at "
                   f"{at(t92)} but no HOST_VEH_STATE_MSG was sent in between (MAPC-67299 "
                   "step 11)")
    return ok(f"0x92 accepted at {at(t92)}, HOST_VEH_STATE_MSG #{veh[0].indices[0]} at "
              f"{at(veh[0].time)}, Running Vision at {at(t_run)}")


def mode_round_trip(mode: str) -> Callable[[Context, Trace], Outcome]:
    def judge(ctx: Context, tr: Trace) -> Outcome:
        done = [m for m in tr.marks_of("mode_done") if m.info["mode"] == mode]
        if not done:
            return skip(f"{mode} was not tried (an earlier flow stopped the script)")
        info = done[0].info
        if not info["ok"]:
            if info.get("problem"):
                return bad(f"{mode}: {info['problem']} (state {info['state']} at "
                           f"{at(done[0].time)})")
            return unsure(f"{mode} not reached or no result within the timeout (state "
                          f"{info['state']})")
        back = [m for m in tr.marks_of("mode_back") if m.info["mode"] == mode]
        if not back or not back[0].info["ok"]:
            return bad(f"{mode} reached at {at(info['entered'])} but Running Vision did not come "
                       "back after Switch EyeQ Application (vision)")
        res = info.get("result") or {}
        if mode != "DV" and not res.get("ok"):
            return bad(f"{mode} finished with an error: {res}")
        detail = "" if mode == "DV" else f", result {res.get('mode')} ok"
        return ok(f"{mode} entered at {at(info['entered'])}{detail}, back in Running Vision at "
                  f"{at(back[0].time)}")
    return judge


def fatal22_flow(ctx: Context, tr: Trace) -> Outcome:
    reports = _state_reports(tr)
    fatal = [r for r in reports if r[3] == FATAL_INTRINSIC]
    if not fatal:
        return unsure("no Fatal_Error 22 was reported for the 0x84 of an empty NVM")
    t_fatal = fatal[0][0]
    reads = [p.reply for p in mesp_pairs(tr) if p.request.name == "FFSReadFile"
             and p.request.time >= t_fatal and p.reply is not None]
    if not reads or ret_of(reads[0]) != 0:
        return bad(f"Fatal 22 at {at(t_fatal)}, but FFS Read File of {EEPROM_FILE} failed")
    running = [r for r in reports if r[1] == RUNNING_VISION and r[0] > t_fatal and r[3] == 0]
    if not running:
        return bad(f"Fatal 22 at {at(t_fatal)}: after the NVM update and restart Running "
                   "Vision was not reached")
    return ok(f"Fatal 22 at {at(t_fatal)}, EEPROM read (reply #{reads[0].indices[-1]}), "
              f"Running Vision with the new 0x84 at {at(running[0][0])}")


# -- the host under test ----------------------------------------------------------------------
def host_versions(ctx: Context, tr: Trace) -> Outcome:
    """MAPC-67299 step 12: Get EyeQ Versions during the power-on init; "once per ignition cycle"
    is said to be sufficient, not required, so a repeat is advice."""
    reqs = [p for p in mesp_pairs(tr, dut_asks=True) if p.request.name == "GetEyeQVersions"]
    if not reqs:
        return bad("the host never asked Get EyeQ Versions in this ignition cycle "
                   "(MAPC-67299 step 12: send it during the power-on init sequence)")
    answered = [p for p in reqs if p.reply is not None and ret_of(p.reply) == 0]
    if answered:
        t_ok = answered[0].reply.time  # type: ignore[union-attr]
        after = [p for p in reqs if p.request.time > t_ok]
        if after:
            return advise(f"{len(reqs)} request(s) in the ignition cycle, the first positive "
                          f"reply at {at(t_ok)}",
                          f"asked again at {at(after[0].request.time)}; MAPC-67299 step 12 "
                          "says once per ignition cycle is enough")
    return ok(f"{len(reqs)} request(s) in the ignition cycle, none after the positive reply "
              "(MAPC-67299 step 12)")


RETRY_WITHIN = DEADLINE + 0.5  # the request's 500 ms deadline (M6), then half a second


def host_retry(ctx: Context, tr: Trace) -> Outcome:
    """M6: a request not answered within 500 ms is retried with a new tag; we withhold the
    reply to the host's first Get EyeQ Versions (MAPC-67299 step 12)."""
    marks = tr.marks_of("reply_withheld")
    if not marks:
        return skip("the host sent no Get EyeQ Versions request, so no reply was withheld")
    # a reset soon after a withheld reply starts the host's requests over (play.eyeq)
    usable = [msg for msg in marks if not any(
        msg.time < r <= msg.time + RETRY_WITHIN + ctx.slack for r in tr.resets())]
    if not usable:
        return skip(f"a reset followed each of the {len(marks)} withheld replies within "
                    f"{RETRY_WITHIN:.1f} s")
    mark = usable[0]
    time, tag = mark.time, int(mark.info["tag"])
    end = time + RETRY_WITHIN + ctx.slack
    if tr.end < end:
        return skip(f"the session ended {tr.end - time:.2f} s after the withheld reply at "
                    f"{at(time)}")
    again = [msg for msg in tr.dut_msgs("GetEyeQVersions")
             if is_request(msg) and time < msg.time <= end]
    if not again:
        return bad(f"the reply to Get EyeQ Versions (tag {tag}) sent at {at(time)} was withheld; "
                   f"the host did not retry within {RETRY_WITHIN:.1f} s (M6: a timed-out "
                   "request is retried with a new tag)", [(time, end, RETRY_WITHIN)])
    msg = again[0]
    new_tag = int(msg.header.get("counter", -1))
    if new_tag == tag:
        return bad(f"Get EyeQ Versions retried at {at(msg.time)} with the same tag {tag} "
                   "(M6: a new tag)")
    return ok(f"the reply to Get EyeQ Versions (tag {tag}) at {at(time)} was withheld; retried "
              f"{1e3 * (msg.time - time):.0f} ms later with tag {new_tag}")


def host_fatal22(ctx: Context, trs: dict[str, Trace]) -> Outcome:
    judged = []
    for name, tr in trs.items():
        fatal = [m for m in tr.our_msgs("EYEQ_DIAGNOSTIC_MSG")
                 if m.fields.get("Fatal_Error") == FATAL_INTRINSIC]
        if not fatal:
            continue
        time = fatal[0].time
        reads = [m for m in tr.dut_msgs("FFSReadFile") if is_request(m) and m.time >= time
                 and m.fields.get("filename") == EEPROM_FILE]
        if not reads or reads[0].time - time > 1.0:
            until = reads[0].time if reads else tr.end
            return bad(f"session {name}: Fatal_Error 22 reported at {at(time)}, no FFS Read File "
                       f"of {EEPROM_FILE} within 1 s (§7.1.3 step 4)",
                       [(time, until, max(until - time - 1.0, 0.0) if reads else 1.0)])
        judged.append(f"{name}: Fatal 22 at {at(time)} -> FFS read at {at(reads[0].time)}")
    if not judged:
        return unsure("Fatal 22 was never reported")
    return ok("; ".join(judged))


# How long a host must be watched, quiet, after a bad EEPROM before "it stopped" means anything:
# a host that carried on or retries shows itself within a reply deadline (M6) and half a second
QUIET_FOR = RETRY_WITHIN


def host_eeprom_bad(ctx: Context, tr: Trace) -> Outcome:
    """§7.1.3 step 6: after a bad EEPROM CRC "the unit is failed": no init, switch, reset or
    HOST_VEH_STATE_MSG for :data:`QUIET_FOR` after the reply (a host that left sooner is
    inconclusive)."""
    served = [m for m in tr.our_msgs("FFSReadFile") if is_reply(m)]
    if not served:
        return unsure("the host did not read the EEPROM, so its reaction to a bad CRC is unknown")
    time = served[0].time
    later = [m for m in tr.dut_msgs() if m.time > time and (
        m.name in ("EventCalibrationTool", "SwitchEyeQApplication", "HOST_VEH_STATE_MSG"))]
    resets = [r.time for r in tr.marks_of("reset_line") if r.time > time]
    if later:
        return bad(f"EEPROM with a bad CRC-16 served at {at(time)}, yet the host sent "
                   f"{later[0].name}"
                   f" at {at(later[0].time)} (§7.1.3 step 6: the unit is failed)")
    if resets:
        return bad(f"EEPROM with a bad CRC-16 served at {at(time)}, yet the host reset us at "
                   f"{at(resets[0])}")
    watched = tr.end - time
    if watched < QUIET_FOR - 1e-9:
        left = tr.first_mark("peer_left")
        why = (f"the host closed the link at {at(left.time)}" if left is not None
               else "the session ended")
        return unsure(f"EEPROM with a bad CRC-16 served at {at(time)}; {why} {watched:.2f} s "
                      "later, "
                      f"before the {QUIET_FOR:.1f} s a host must be watched to show it stopped "
                      "(a MESP reply deadline, 500 ms, and half a second: M6); a host that "
                      "stops keeps its port open")
    return ok(f"EEPROM with a bad CRC-16 served at {at(time)}; the host stopped (no init, switch, "
              f"reset or HOST_VEH_STATE_MSG for {watched:.2f} s, at least {QUIET_FOR:.1f} s)")


def host_boot_resets(ctx: Context, tr: Trace) -> Outcome:
    """§7.1.5.3 states no reaction to a failing boot: the number of resets is advice."""
    mark = tr.first_mark("resets")
    if mark is None:
        return skip("the boot-failure session did not run")
    times = list(mark.info["times"])
    boots = len(tr.our_msgs("EYEQ_BOOT_STATUS_MSG"))
    seen = (f"{boots} failing boot status message(s), {len(times)} reset(s) "
            f"(watched until {at(tr.end)})")
    if len(times) > 3:
        return advise(seen, f"{len(times)} resets after failing boots "
                      f"({', '.join(at(t) for t in times[:6])}); we recommend at most 3, then "
                      "reporting the unit failed (§7.1.5.3 states no limit)")
    return ok(f"{seen}; §7.1.5.3 states no limit on resets")


def host_eyeq_reset(ctx: Context, tr: Trace) -> Outcome:
    mark = tr.first_mark("our_reset")
    if mark is None:
        return skip("we did not reset")
    time = mark.time
    inits = [m for m in tr.dut_msgs("EventCalibrationTool") if is_request(m) and m.time > time]
    stages = [m.fields.get("ct_stage") for m in inits]
    if 0x92 not in stages:
        return bad(f"we reset at {at(time)}; the host sent no Init_Params_Vision (0x92) afterwards "
                   f"(init stages seen: {stages})")
    t92 = inits[stages.index(0x92)].time
    veh = [m for m in tr.dut_msgs("HOST_VEH_STATE_MSG") if m.time > t92]
    if not veh:
        return bad(f"after our reset at {at(time)} and 0x92 at {at(t92)}, no HOST_VEH_STATE_MSG")
    return ok(f"we reset at {at(time)}; init {', '.join(f'0x{s:02X}' for s in stages)} again, "
              f"HOST_VEH_STATE_MSG from {at(veh[0].time)}")


def host_stale(ctx: Context, tr: Trace) -> Outcome:
    mark, start = tr.first_mark("stale_end"), tr.first_mark("stale_start")
    if mark is None or start is None:
        return skip("no DASP stream was stopped")
    detected = mark.info["detected"]
    stream = mark.info["stream"]
    if detected is None:
        return unsure(f"{stream} stopped at {at(start.time)}: a host under test reports stale "
                      "streams off the SPI link, so this is not observable here")
    if not detected:
        return bad(f"{stream} silent for {mark.time - start.time:.2f} s and the host did not "
                   "flag it as stale")
    return ok(f"{stream} stopped; flagged stale by {at(mark.time)}")


def host_init_order(ctx: Context, tr: Trace) -> Outcome:
    pending = [m for m in tr.our_msgs("EYEQ_DIAGNOSTIC_MSG") if m.fields.get("Main_State") == 1]
    reqs = [m for m in tr.dut_msgs("EventCalibrationTool") if is_request(m)]
    if not reqs:
        return unsure("the host sent no init message")
    if not pending or reqs[0].time < pending[0].time:
        return bad(f"init request #{reqs[0].indices[0]} at {at(reqs[0].time)} before we "
                   "reported Pending Vision (MAPC-67299 step 8)")
    stages = [m.fields.get("ct_stage") for m in reqs]
    if 0x84 in stages and 0x92 in stages and stages.index(0x92) < stages.index(0x84):
        return bad(f"0x92 sent before 0x84 (order {stages}; §7.1.3 steps 1-2)")
    accepted = [rep.time for req, rep in _ect_replies(tr, 0x92, dut_asks=True) if ret_of(rep) == 0]
    veh = tr.dut_msgs("HOST_VEH_STATE_MSG")
    if veh and (not accepted or veh[0].time < accepted[0]):
        return bad(f"HOST_VEH_STATE_MSG #{veh[0].indices[0]} at {at(veh[0].time)} before 0x92 "
                   "was accepted (MAPC-67299 step 11)")
    return ok(f"init after Pending Vision, order {[f'0x{s:02X}' for s in stages[:4]]}, "
              "HOST_VEH_STATE_MSG only after 0x92 was accepted")

