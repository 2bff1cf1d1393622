"""The host emulator's constants, configuration, counters and transitions (the data the rest of
the project imports from :mod:`eyeq_spi.host.host`, which re-exports them)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from eyeq_spi.catalog.bringup import (
    APP_DV,
    APP_SPC,
    APP_TAC,
    APP_VISION,
    PENDING_SPC,
    PENDING_TAC,
    PENDING_VISION,
)
from eyeq_spi.host.machine import HostEvent, HostState
from eyeq_spi.link.connection import LinkConfig

APP_IDS = {"VISION": APP_VISION, "TAC": APP_TAC, "SPC": APP_SPC, "DV": APP_DV}
PENDING_OF = {"TAC": PENDING_TAC, "SPC": PENDING_SPC, "VISION": PENDING_VISION}
STAGE_OF = {"TAC": 0x85, "SPC": 0x82}
VALID = 0x69  # host_sync_timestamp_us_valid
STALE_CHECK = 0.010  # stale streams are looked for every 10 ms


@dataclass
class HostConfig:
    sw: str | None = None
    camera_only_aeb: bool = False  # send IPB 0x78 and PCW 0x79 before 0x92
    ipb_params: bytes = b"\x00"  # the seed prints no 0x78 bit table: sent as opaque bytes
    veh_state_rate: float = 66.67  # §7.1.2.2
    poll_interval: float = 0.1  # Get Extended State polling
    boot_timeout: float = 2.0  # no boot status within this -> reset and retry
    boot_strikes: int = 3
    stale_periods: float = 3.0  # a DASP stream is stale after this many periods of silence
    max_resets: int = 3  # EEPROM-driven resets before giving up (Fatal 22 that never clears)
    ack_timeout: float | None = None  # link timings; None: the seed's defaults (§6)
    transmit_timeout: float | None = None


@dataclass
class HostCounters:
    received: Counter[str] = field(default_factory=Counter)
    sent: Counter[str] = field(default_factory=Counter)
    dasp_counter_gaps: int = 0
    e2e_errors: int = 0
    decode_errors: int = 0
    stale_events: Counter[str] = field(default_factory=Counter)
    ignored_events: int = 0
    eyeq_resets: int = 0  # resets of the EyeQ the host did not ask for (detected)
    eyeq_resets_asked: int = 0  # the host reset it: reset line, or a soft reset (Switch)
    restarts_answered: int = 0  # the EyeQ's link restarts that answered our own reset (L10)
    boot_failures: int = 0
    rx_times: dict[str, list[float]] = field(default_factory=dict)
    tx_times: list[float] = field(default_factory=list)


@dataclass(frozen=True)
class Transition:
    time: float
    src: HostState
    event: HostEvent
    dst: HostState
    detail: str = ""


def link_config(role: str, ack: float | None, transmit: float | None) -> LinkConfig:
    cfg = LinkConfig(role=role)  # type: ignore[arg-type]
    if ack is not None:
        cfg.ack_timeout = ack
    if transmit is not None:
        cfg.transmit_timeout = transmit
    return cfg
