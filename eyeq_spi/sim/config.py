"""Configuration, fault hooks and counters of the simulated EyeQ."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from eyeq_spi.catalog.bringup import RUNNING_SPC, RUNNING_TAC, RUNNING_VISION


@dataclass
class SimConfig:
    sw: str | None = None  # SW version the EyeQ runs (default: newest in specs/)
    seed: int = 1
    # power-up (§7.1.5.3)
    boot_delay: float = 0.150  # power-up -> EYEQ_BOOT_STATUS_MSG
    app_start_delay: float = 0.100  # boot status -> first 0x41
    boot_version: str = "7.1.23"
    application_version: str | None = None  # None: the release of ``sw``, e.g. "6.0.0"
    eyeq_id: int = 0x4E51_0001
    eyeq_type: int = 4
    api_version: tuple[int, int] | None = None  # None: the release of ``sw``
    sw_version: tuple[int, int] | None = None  # None: the release of ``sw``
    # rates (§7.1.4, §7.1.5)
    dasp_rate: float = 18.0
    # DASP payloads packed in place (sim/dasp_fast.py); False: the reference (Scene.fill +
    # MessageCodec.encode_dasp), which the packer is tested against; None: packed unless
    # EYEQ_SPI_EXACT=1 asks for the references
    dasp_packer: bool | None = None
    diag_rate: float = 37.0
    # scene (numpy model)
    objects: int = 8
    signs: int = 4
    light_spots: int = 4
    flash_mb: int = 64
    tac_duration: float = 2.0  # seconds of TAC/SPC "progress" before results
    ack_timeout: float | None = None  # link timings; None: the seed's defaults (§6)
    transmit_timeout: float | None = None
    # -- fault hooks ------------------------------------------------------------------------
    boot_test_failures: int = 0  # TestResults bits reported at boot...
    boot_failures: int = 0  # ...for this many power-ups (then the boot passes)
    corrupt_eeprom_crc: bool = False  # FFS read returns an image whose CRC does not match
    fatal_error: int | None = None  # force this Fatal_Error in 0x41 (22 = intrinsic mismatch)
    reply_delay: float = 0.0  # every MESP reply leaves this late
    delay_replies: dict[str, float] = field(default_factory=dict)  # per function: extra delay
    drop_replies: dict[str, int] = field(default_factory=dict)  # per function: drop first N
    reset_at: float | None = None  # the EyeQ resets itself at this time (seconds)
    stop_dasp: dict[str, float] = field(default_factory=dict)  # message -> time it stops
    tac_error: int | None = None  # TAC finishes with this tac_error instead of NO_ERROR


VEH_STATE_STALE = 3 / 66.67  # three HOST_VEH_STATE periods (§7.1.2.2: 66.67 Hz)
MODE_OF_STATE = {RUNNING_VISION: "APP", RUNNING_TAC: "TAC", RUNNING_SPC: "SPC"}


@dataclass
class SimCounters:
    """What the simulator really received (reported in 0xA0)."""

    msg20_rx: int = 0
    bad_hdr: int = 0
    bad_seq: int = 0
    msg_tx: int = 0
    rolling_count_echo: int = 0
    e2e_errors: int = 0  # HOST_VEH_STATE structures rejected by their CRC or counter (D5)
    counter_gaps: int = 0  # DASP counter steps other than +1 (D1), not wrapped like bad_seq
    bad_hdr_total: int = 0  # bad_hdr, not wrapped
    veh_state_stale: int = 0  # HOST_VEH_STATE silent > 3 periods in Running Vision (§7.1.2.2)
    mesp_requests: int = 0
    # MESP replies the host waits for in vain (M6: no reply within the deadline is a timeout):
    # dropped (--drop-reply, or still delayed when the EyeQ reset) or sent past the deadline
    mesp_replies_dropped: int = 0
    mesp_replies_late: int = 0
    received: Counter[str] = field(default_factory=Counter)
    rejected_values: int = 0  # vehicle signals not valid, not finite or outside the seed range
    edr_triggers: list[dict[str, Any]] = field(default_factory=list)
    calibration_events: list[tuple[int, int]] = field(default_factory=list)  # (stage, ret)
    boots: int = 0
    self_resets: int = 0  # resets of its own (SimConfig.reset_at), no host asked for them
    vision_switches: int = 0  # accepted Switch EyeQ Application to Vision: a reset (L10)
    sent: Counter[str] = field(default_factory=Counter)
