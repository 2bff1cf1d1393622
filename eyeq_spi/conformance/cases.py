"""The cases, as data: ID, title, seed 004 section, requirement ID (MAPC-…), decision, group,
which implementation under test it applies to, the session whose trace it reads, the script
steps it needs, and its judge. DASP rate cases and MESP function cases are generated from
``specs/`` (one per message and mode, one per M3 function), so a release's table is its suite.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from eyeq_spi.catalog.messages import catalog
from eyeq_spi.conformance.judges import app as A  # noqa: N812 - short names keep the table
from eyeq_spi.conformance.judges import flow as F  # noqa: N812
from eyeq_spi.conformance.judges import link as L  # noqa: N812
from eyeq_spi.conformance.model import ALL_SESSIONS, CONTENT, TIMING, Case

EYEQ, HOST, BOTH = ("eyeq",), ("host",), ("eyeq", "host")
# the suite's version, stated in every report: raised whenever a case, its rule or the meaning
# of a verdict changes, so that two signed reports of one version judged the same things
SUITE_VERSION = "2026.11-4"

# seed sections and requirement IDs of the M3 functions (request / response)
MESP_REFS = {
    "GetEyeQExtendedState": ("7.1.1.1.1", "MAPC-67312, MAPC-67314"),
    "FFSReadFile": ("7.1.1.1.2", "MAPC-67318, MAPC-67320"),
    "ComputeHash": ("7.1.1.1.3", "MAPC-67322, MAPC-67324"),
    "SwitchEyeQApplication": ("7.1.1.1.4", "MAPC-67329, MAPC-67331"),
    "GetEyeQVersions": ("7.1.1.1.5", "MAPC-67334, MAPC-67336"),
    "SendParamsToCalibrationTool": ("7.1.1.1.6", "MAPC-67339, MAPC-67341"),
    "EventCalibrationTool": ("7.1.1.7", "MAPC-67344, MAPC-67346"),
}
# the script step that exercises each function (the others run during bring-up and flows)
MESP_STEP = {"SwitchEyeQApplication": "flows", "EventCalibrationTool": "early_init"}


def _c(id: str, title: str, section: str, req: str | None, dec: str | None, group: str,
       duts: tuple[str, ...], judge: Callable[..., Any], *, session: str = "main",
       needs: tuple[str, ...] = (), rule: str = CONTENT) -> Case:
    return Case(id, title, section, req, dec, group, duts, judge, session, needs, rule)


def _static() -> list[Case]:
    link = ("link",)
    return [
        # -- link (§6) ---------------------------------------------------------------------
        _c("LINK-SIZE", "every transfer is exactly 128 bytes", "6", "MAPC-67290", "L1, L8",
           "link", BOTH, L.link_size),
        _c("LINK-CRC", "CRC-16 (DATA: header+data, ACK/NAK: header), D and R valid", "6",
           "MAPC-67290", "L1, L2, L3", "link", BOTH, L.link_crc),
        _c("LINK-NUM", "DATA frames numbered +1 mod 4096, 0 after a reset", "6", "MAPC-67290",
           "L4, L10", "link", BOTH, L.link_num),
        _c("LINK-ACK", "every accepted DATA frame is ACKed, RSP = its NUM, within ackTimeout", "6",
           "MAPC-67290", "L5", "link", BOTH, L.link_ack, rule=TIMING),
        _c("LINK-NAK-CRC", "a frame with a bad CRC is NAKed 0x002", "6", "MAPC-67290", "L5",
           "link", BOTH, L.nak_crc, needs=link),
        _c("LINK-NAK-FORMAT", "a frame with an invalid D or R is NAKed 0x011", "6",
           "MAPC-67290", "L2, L5", "link", BOTH, L.nak_format, needs=link),
        _c("LINK-NAK-WINDOW", "a NUM outside the receive window is NAKed 0x001", "6",
           "MAPC-67290", "L5, L6", "link", BOTH, L.nak_window, needs=link),
        _c("LINK-DUP", "a duplicate frame is ACKed again and dropped", "6", "MAPC-67290",
           "L6, L6a", "link", BOTH, L.link_dup, needs=link),
        _c("LINK-RESYNC", "resynchronises after our simulated reset (at most 3 NAKs)", "6",
           "MAPC-67290", "L6, L10", "link", BOTH, L.link_resync, needs=link),
        _c("LINK-PAD", "ACK and NAK frames carry 122 pad bytes set to 0", "6", "MAPC-67290",
           "L1", "link", BOTH, L.link_pad),
        _c("LINK-NORESEND", "unacknowledged DATA frames are never resent", "6", "MAPC-67290",
           "L7", "link", BOTH, L.link_noresend, needs=link),
        _c("LINK-WINDOW", "at most W = 8 DATA frames unacknowledged (ACK blackout)", "6",
           "MAPC-67290", "L7", "link", BOTH, L.link_window, needs=link, rule=TIMING),
        _c("LINK-TXTIMEOUT", "the frames of one message span at most transmitTimeout", "6",
           "MAPC-67290", "L7", "link", BOTH, L.link_txtimeout, rule=TIMING),
        _c("LINK-GAP", "inter-frame gap >= 200 µs (EyeQ) / 500 µs (host), real time only",
           "6", "MAPC-67290", "L7", "link", BOTH, L.link_gap, rule=TIMING),
        # -- transport (§6.1-6.2) ----------------------------------------------------------
        _c("TP-FORMAT", "single, first and consecutive frame formats; no interleaving",
           "6.1, 6.2", "MAPC-67292, MAPC-67294, MAPC-67296", "T1-T5", "transport", BOTH,
           L.tp_format),
        _c("TP-TID", "the transfer ID increments per multi-frame message", "6.2.1",
           "MAPC-67296", "T3", "transport", EYEQ, L.tp_tid),
        _c("TP-LIMIT", "receive limit (EyeQ 512, host 8191): one byte more is NAKed 0x011",
           "6", "MAPC-67290", "T6", "transport", BOTH, L.tp_limit, needs=link),
        _c("TP-ABORT", "a NUM gap or 25 ms of silence aborts a transfer", "6.2",
           "MAPC-67294", "T6", "transport", EYEQ, L.tp_abort, needs=link),
        # -- MESP (§7.1.1) -------------------------------------------------------------------
        _c("MESP-TAG", "replies echo service, function and tag counter, bit 7 set", "7.1.1",
           None, "M1", "mesp", EYEQ, A.mesp_tag),
        _c("MESP-DEADLINE", "every reply within 500 ms", "7.1.1", None, "M6", "mesp", EYEQ,
           A.mesp_deadline, rule=TIMING),
        _c("MESP-BADPARAM", "bad parameters give ret != 0", "7.1.1", None, "M2", "mesp", EYEQ,
           A.mesp_bad_params, needs=("mesp",)),
        _c("MESP-UNKNOWN", "an unknown service or function gives ret 2", "7.1.1.1",
           "MAPC-67305", "M2", "mesp", EYEQ, A.mesp_unknown, needs=("mesp",)),
        _c("MESP-REQTAG", "request tags count +1 per request, bits 6 and 7 clear", "7.1.1",
           None, "M1", "mesp", HOST, A.mesp_request_tags),
        _c("MESP-LATE", "an unmatched reply is ignored by the host", "7.1.1", None, "M1",
           "mesp", HOST, A.mesp_unmatched),
        # -- DASP (§7.1.2) -------------------------------------------------------------------
        _c("DASP-COUNTER", "DASP counter +1 per message of each data ID", "7.1.2",
           "MAPC-67350", "D1", "dasp", BOTH, A.dasp_counter),
        _c("DASP-LENGTH", "payload length of the release; known data IDs", "7.1.2",
           "MAPC-67350", "D3, D4", "dasp", BOTH, A.dasp_length),
        _c("DASP-E2E", "every crc_16 and rollingFrameCount correct", "7.1.2", None, "D5",
           "dasp", BOTH, A.dasp_e2e),
        _c("DASP-UNUSED", "unused bitfield bits are sent as 1", "7.1.2", "MAPC-67350", "D2",
           "dasp", BOTH, A.dasp_unused),
        _c("DIAG-RATE", "EYEQ_DIAGNOSTIC_MSG (0x41) at 37 Hz (-25/+50 ms)", "7.1.5",
           "MAPC-67399", None, "dasp", EYEQ, A.diag_rate, rule=TIMING),
        # -- flows ---------------------------------------------------------------------------
        _c("FLOW-BOOT-FIRST", "EYEQ_BOOT_STATUS_MSG is the first message", "7.1.5.3",
           "MAPC-67299, MAPC-67408", None, "flows", EYEQ, F.boot_first),
        _c("FLOW-PENDING", "Pending Vision is reported before any init is accepted", "7.1.1.1.1",
           "MAPC-67299", None, "flows", EYEQ, F.pending_before_init, needs=("early_init",)),
        _c("FLOW-RUNNING", "Running Vision only after 0x92 and a HOST_VEH_STATE_MSG", "7.1.2.2",
           "MAPC-67299", None, "flows", EYEQ, F.running_after_init),
        _c("FLOW-TAC", "TAC round trip: switch, 0x85, results, back to vision", "7.1.1.1.4",
           "MAPC-67329, MAPC-67421", None, "flows", EYEQ, F.mode_round_trip("TAC"),
           needs=("flows",)),
        _c("FLOW-SPC", "SPC round trip: switch, 0x82, results, back to vision", "7.1.1.1.4",
           "MAPC-67329, MAPC-67423", None, "flows", EYEQ, F.mode_round_trip("SPC"),
           needs=("flows",)),
        _c("FLOW-DV", "DV round trip: switch to 0x05, back to vision", "7.1.1.1.4",
           "MAPC-67329, MAPC-67426", "M7", "flows", EYEQ, F.mode_round_trip("DV"),
           needs=("flows",)),
        _c("FLOW-FATAL22", "a mismatched 0x84 gives Fatal 22; EEPROM read; vision after",
           "7.1.3", "MAPC-67363", "I2", "flows", EYEQ, F.fatal22_flow),
        # -- the host under test -----------------------------------------------------------
        _c("HOST-VERSIONS", "Get EyeQ Versions during the power-on init (again: advice)", "6",
           "MAPC-67299",
           None, "host", HOST, F.host_versions),
        _c("HOST-RETRY", "a request left unanswered is retried with a new tag", "7.1.1", None,
           "M6", "host", HOST, F.host_retry, rule=TIMING),
        _c("HOST-INIT-ORDER", "0x84 then 0x92 after Pending Vision; DASP after 0x92", "7.1.3",
           "MAPC-67363, MAPC-67299", "M5", "host", HOST, F.host_init_order),
        _c("HOST-FATAL22", "Fatal 22 -> the host reads the EEPROM", "7.1.3", "MAPC-67363",
           "I2", "host", HOST, F.host_fatal22, session=ALL_SESSIONS, rule=TIMING),
        _c("HOST-EEPROM-BAD", "a bad EEPROM CRC -> the host stops", "7.1.3", "MAPC-67363",
           "I2", "host", HOST, F.host_eeprom_bad, session="eeprom_bad"),
        _c("HOST-BOOT-RESETS", "a failing boot: resets counted (more than 3: advice)", "7.1.5.3",
           "MAPC-67408",
           None, "host", HOST, F.host_boot_resets, session="boot_fail"),
        _c("HOST-EYEQ-RESET", "an EyeQ reset -> the bring-up runs again", "7.1.3",
           "MAPC-67363, MAPC-67299", "L10, L10a", "host", HOST, F.host_eyeq_reset),
        _c("HOST-STALE", "a stale DASP stream is detected", "7.1.4", "MAPC-67370", None, "host",
           HOST, F.host_stale),
    ]


def _generated(sw: str | None) -> list[Case]:
    cat = catalog()
    key = cat.sw(sw)
    out: list[Case] = []
    for f in cat.mesp:
        section, req = MESP_REFS.get(f.name, ("7.1.1.1", None))
        step = MESP_STEP.get(f.name, "mesp")
        out.append(_c(f"MESP-FN-{f.name}", f"{f.name} (0x{f.service:02X}/0x{f.function:02X})"
                      " answered with ret 0 and correct parameters", section, req, "M3", "mesp",
                      EYEQ, A.mesp_function(f.name), needs=(step,)))
    for m in cat.messages:
        if m.protocol != "DASP" or not m.exists_in(key) or m.rate_hz is None:
            continue
        duts = EYEQ if m.direction == "e2h" else HOST
        req = "MAPC-67370" if m.direction == "e2h" else "MAPC-67355"
        for mode in m.modes:
            needs = () if mode == "APP" else ("flows",)
            lo, hi = m.tolerance_ms or (0.0, 0.0)
            out.append(_c(f"DASP-RATE-{mode}-{m.name}",
                          f"{m.name} (0x{m.data_id:02X}) in {mode} at {m.rate_hz} Hz "
                          f"({lo:+g}/{hi:+g} ms)", m.section or "7.1.4", req, "D1",
                          "dasp", duts, A.dasp_rate(m.name, mode), needs=needs,
                          rule=TIMING))
    return out


def all_cases(sw: str | None = None) -> list[Case]:
    return _static() + _generated(sw)


def cases_for(dut: str, sw: str | None = None) -> list[Case]:
    return [c for c in all_cases(sw) if dut in c.duts]
