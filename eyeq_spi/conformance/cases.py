"""The cases, as data. DASP rate cases and MESP function cases are generated from ``specs/`` (one
per message and mode, one per M3 function), so a release's table is its suite."""

from __future__ import annotations

from eyeq_spi.catalog.messages import catalog
from eyeq_spi.conformance.judges import app, flow, link
from eyeq_spi.conformance.model import ALL_SESSIONS, TIMING, Case
from eyeq_spi.link.frame import NakReason

EYEQ, HOST, BOTH = ("eyeq",), ("host",), ("eyeq", "host")
CRC, FORMAT, WINDOW = NakReason.CRC_MISMATCH, NakReason.FORMAT_ERROR, NakReason.OUT_OF_WINDOW
LINK = ("link",)  # the script step of the link cases that inject frames
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


# the cases written by hand (the generated ones follow from specs/ in _generated)
STATIC_CASES: tuple[Case, ...] = (
    # -- link (§6) ---------------------------------------------------------------------
    Case("LINK-SIZE", "every transfer is exactly 128 bytes", "6", "MAPC-67290", "L1, L8",
         "link", BOTH, link.link_size),
    Case("LINK-CRC", "CRC-16 (DATA: header+data, ACK/NAK: header), D and R valid", "6",
         "MAPC-67290", "L1, L2, L3", "link", BOTH, link.link_crc),
    Case("LINK-NUM", "DATA frames numbered +1 mod 4096, 0 after a reset", "6", "MAPC-67290",
         "L4, L10", "link", BOTH, link.link_num),
    Case("LINK-ACK", "every accepted DATA frame is ACKed, RSP = its NUM, within ackTimeout", "6",
         "MAPC-67290", "L5", "link", BOTH, link.link_ack, rule=TIMING),
    Case("LINK-NAK-CRC", "a frame with a bad CRC is NAKed 0x002", "6", "MAPC-67290", "L5",
         "link", BOTH, link.nak_probe(CRC, "nak_crc"), needs=LINK),
    Case("LINK-NAK-FORMAT", "a frame with an invalid D or R is NAKed 0x011", "6",
         "MAPC-67290", "L2, L5", "link", BOTH,
         link.nak_probe(FORMAT, "nak_format_d", "nak_format_r"), needs=LINK),
    Case("LINK-NAK-WINDOW", "a NUM outside the receive window is NAKed 0x001", "6",
         "MAPC-67290", "L5, L6", "link", BOTH, link.nak_probe(WINDOW, "nak_window"),
         needs=LINK),
    Case("LINK-DUP", "a duplicate frame is ACKed again and dropped", "6", "MAPC-67290",
         "L6, L6a", "link", BOTH, link.link_dup, needs=LINK),
    Case("LINK-RESYNC", "resynchronises after our simulated reset (at most 3 NAKs)", "6",
         "MAPC-67290", "L6, L10", "link", BOTH, link.link_resync, needs=LINK),
    Case("LINK-PAD", "ACK and NAK frames carry 122 pad bytes set to 0", "6", "MAPC-67290",
         "L1", "link", BOTH, link.link_pad),
    Case("LINK-NORESEND", "unacknowledged DATA frames are never resent", "6", "MAPC-67290",
         "L7", "link", BOTH, link.link_noresend, needs=LINK),
    Case("LINK-WINDOW", "at most W = 8 DATA frames unacknowledged (ACK blackout)", "6",
         "MAPC-67290", "L7", "link", BOTH, link.link_window, needs=LINK, rule=TIMING),
    Case("LINK-TXTIMEOUT", "the frames of one message span at most transmitTimeout", "6",
         "MAPC-67290", "L7", "link", BOTH, link.link_txtimeout, rule=TIMING),
    Case("LINK-GAP", "inter-frame gap >= 200 µs (EyeQ) / 500 µs (host), real time only",
         "6", "MAPC-67290", "L7", "link", BOTH, link.link_gap, rule=TIMING),
    # -- transport (§6.1-6.2) ----------------------------------------------------------
    Case("TP-FORMAT", "single, first and consecutive frame formats; no interleaving",
         "6.1, 6.2", "MAPC-67292, MAPC-67294, MAPC-67296", "T1-T5", "transport", BOTH,
         link.tp_format),
    Case("TP-TID", "the transfer ID increments per multi-frame message", "6.2.1",
         "MAPC-67296", "T3", "transport", EYEQ, link.tp_tid),
    Case("TP-LIMIT", "receive limit (EyeQ 512, host 8191): one byte more is NAKed 0x011",
         "6", "MAPC-67290", "T6", "transport", BOTH, link.tp_limit, needs=LINK),
    Case("TP-ABORT", "a NUM gap or 25 ms of silence aborts a transfer", "6.2",
         "MAPC-67294", "T6", "transport", EYEQ, link.tp_abort, needs=LINK),
    # -- MESP (§7.1.1) -------------------------------------------------------------------
    Case("MESP-TAG", "replies echo service, function and tag counter, bit 7 set", "7.1.1",
         None, "M1", "mesp", EYEQ, app.mesp_tag),
    Case("MESP-DEADLINE", "every reply within 500 ms", "7.1.1", None, "M6", "mesp", EYEQ,
         app.mesp_deadline, rule=TIMING),
    Case("MESP-BADPARAM", "bad parameters give ret != 0", "7.1.1", None, "M2", "mesp", EYEQ,
         app.mesp_bad_params, needs=("mesp",)),
    Case("MESP-UNKNOWN", "an unknown service or function gives ret 2", "7.1.1.1",
         "MAPC-67305", "M2", "mesp", EYEQ, app.mesp_unknown, needs=("mesp",)),
    Case("MESP-REQTAG", "request tags count +1 per request, bits 6 and 7 clear", "7.1.1",
         None, "M1", "mesp", HOST, app.mesp_request_tags),
    Case("MESP-LATE", "an unmatched reply is ignored by the host", "7.1.1", None, "M1",
         "mesp", HOST, app.mesp_unmatched),
    # -- DASP (§7.1.2) -------------------------------------------------------------------
    Case("DASP-COUNTER", "DASP counter +1 per message of each data ID", "7.1.2",
         "MAPC-67350", "D1", "dasp", BOTH, app.dasp_counter),
    Case("DASP-LENGTH", "payload length of the release; known data IDs", "7.1.2",
         "MAPC-67350", "D3, D4", "dasp", BOTH, app.dasp_length),
    Case("DASP-E2E", "every crc_16 and rollingFrameCount correct", "7.1.2", None, "D5",
         "dasp", BOTH, app.dasp_e2e),
    Case("DASP-UNUSED", "unused bitfield bits are sent as 1", "7.1.2", "MAPC-67350", "D2",
         "dasp", BOTH, app.dasp_unused),
    Case("DIAG-RATE", "EYEQ_DIAGNOSTIC_MSG (0x41) at 37 Hz (-25/+50 ms)", "7.1.5",
         "MAPC-67399", None, "dasp", EYEQ, app.dasp_rate("EYEQ_DIAGNOSTIC_MSG"), rule=TIMING),
    # -- flows ---------------------------------------------------------------------------
    Case("FLOW-BOOT-FIRST", "EYEQ_BOOT_STATUS_MSG is the first message", "7.1.5.3",
         "MAPC-67299, MAPC-67408", None, "flows", EYEQ, flow.boot_first),
    Case("FLOW-PENDING", "Pending Vision is reported before any init is accepted", "7.1.1.1.1",
         "MAPC-67299", None, "flows", EYEQ, flow.pending_before_init, needs=("early_init",)),
    Case("FLOW-RUNNING", "Running Vision only after 0x92 and a HOST_VEH_STATE_MSG", "7.1.2.2",
         "MAPC-67299", None, "flows", EYEQ, flow.running_after_init),
    Case("FLOW-TAC", "TAC round trip: switch, 0x85, results, back to vision", "7.1.1.1.4",
         "MAPC-67329, MAPC-67421", None, "flows", EYEQ, flow.mode_round_trip("TAC"),
         needs=("flows",)),
    Case("FLOW-SPC", "SPC round trip: switch, 0x82, results, back to vision", "7.1.1.1.4",
         "MAPC-67329, MAPC-67423", None, "flows", EYEQ, flow.mode_round_trip("SPC"),
         needs=("flows",)),
    Case("FLOW-DV", "DV round trip: switch to 0x05, back to vision", "7.1.1.1.4",
         "MAPC-67329, MAPC-67426", "M7", "flows", EYEQ, flow.mode_round_trip("DV"),
         needs=("flows",)),
    Case("FLOW-FATAL22", "a mismatched 0x84 gives Fatal 22; EEPROM read; vision after",
         "7.1.3", "MAPC-67363", "I2", "flows", EYEQ, flow.fatal22_flow),
    # -- the host under test -----------------------------------------------------------
    Case("HOST-VERSIONS", "Get EyeQ Versions during the power-on init (again: advice)", "6",
         "MAPC-67299",
         None, "host", HOST, flow.host_versions),
    Case("HOST-RETRY", "a request left unanswered is retried with a new tag", "7.1.1", None,
         "M6", "host", HOST, flow.host_retry, rule=TIMING),
    Case("HOST-INIT-ORDER", "0x84 then 0x92 after Pending Vision; DASP after 0x92", "7.1.3",
         "MAPC-67363, MAPC-67299", "M5", "host", HOST, flow.host_init_order),
    Case("HOST-FATAL22", "Fatal 22 -> the host reads the EEPROM", "7.1.3", "MAPC-67363",
         "I2", "host", HOST, flow.host_fatal22, session=ALL_SESSIONS, rule=TIMING),
    Case("HOST-EEPROM-BAD", "a bad EEPROM CRC -> the host stops", "7.1.3", "MAPC-67363",
         "I2", "host", HOST, flow.host_eeprom_bad, session="eeprom_bad"),
    Case("HOST-BOOT-RESETS", "a failing boot: resets counted (more than 3: advice)", "7.1.5.3",
         "MAPC-67408",
         None, "host", HOST, flow.host_boot_resets, session="boot_fail"),
    Case("HOST-EYEQ-RESET", "an EyeQ reset -> the bring-up runs again", "7.1.3",
         "MAPC-67363, MAPC-67299", "L10, L10a", "host", HOST, flow.host_eyeq_reset),
    Case("HOST-STALE", "a stale DASP stream is detected", "7.1.4", "MAPC-67370", None, "host",
         HOST, flow.host_stale),
)


def _generated(sw: str | None) -> list[Case]:
    cat = catalog()
    key = cat.sw(sw)
    out: list[Case] = []
    for function in cat.mesp:
        name = function.name
        section, req = MESP_REFS.get(name, ("7.1.1.1", None))
        step = MESP_STEP.get(name, "mesp")
        out.append(Case(f"MESP-FN-{name}",
                        f"{name} (0x{function.service:02X}/0x{function.function:02X})"
                        " answered with ret 0 and correct parameters", section, req, "M3",
                        "mesp", EYEQ, app.mesp_function(name), needs=(step,)))
    for msg in cat.messages:
        if msg.protocol != "DASP" or not msg.exists_in(key) or msg.rate_hz is None:
            continue
        duts = EYEQ if msg.direction == "e2h" else HOST
        req = "MAPC-67370" if msg.direction == "e2h" else "MAPC-67355"
        for mode in msg.modes:
            needs = () if mode == "APP" else ("flows",)
            lo, hi = msg.tolerance_ms or (0.0, 0.0)
            out.append(Case(f"DASP-RATE-{mode}-{msg.name}",
                            f"{msg.name} (0x{msg.data_id:02X}) in {mode} at {msg.rate_hz} Hz "
                            f"({lo:+g}/{hi:+g} ms)", msg.section or "7.1.4", req, "D1",
                            "dasp", duts, app.dasp_rate(msg.name, mode), needs=needs,
                            rule=TIMING))
    return out


def all_cases(sw: str | None = None) -> list[Case]:
    return [*STATIC_CASES, *_generated(sw)]


def cases_for(dut: str, sw: str | None = None) -> list[Case]:
    return [c for c in all_cases(sw) if dut in c.duts]
