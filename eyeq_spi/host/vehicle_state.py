"""HOST_VEH_STATE_MSG (seed 004 §7.1.2.2): the host's one periodic DASP message, at
``HostConfig.veh_state_rate`` (66.67 Hz) from Wait Running on: its period, counters and
encoding (a fresh ``zero_values()`` dict filled by
:func:`~eyeq_spi.host.scenario.veh_state_values`); the host's entry actions start and stop it."""

from __future__ import annotations

from eyeq_spi.catalog.messages import sw_release
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.host.config import HostConfig
from eyeq_spi.host.scenario import Scenario, veh_state_values

NAME = "HOST_VEH_STATE_MSG"


class VehicleStateSender:
    """When the next HOST_VEH_STATE_MSG is due (``next_due``, None while the host sends none),
    and its bytes. The rolling, DASP and E2E counters run on across EyeQ resets (one unbroken
    sequence in a capture); only a new ignition cycle starts them afresh (:meth:`new_cycle`)."""

    def __init__(self, codec: MessageCodec, config: HostConfig) -> None:
        self.codec = codec
        self.config = config
        self.next_due: float | None = None
        self.rolling = 0
        self.dasp_counter = 0
        self.e2e = E2EState()

    def new_cycle(self) -> None:
        """A new ignition cycle: the counters start afresh."""
        self.e2e = E2EState()
        self.dasp_counter = self.rolling = 0

    def warm_up(self) -> None:
        """Encode the message once by the reference (its codec built before real time)."""
        msg = self.codec.message(NAME)
        self.codec.encode_dasp(msg.name, self.codec.layout(msg).zero_values(), 0, E2EState())

    def due(self, now: float) -> bool:
        return self.next_due is not None and now >= self.next_due

    def advance(self, now: float) -> None:
        """One period on from the message just sent (never into the past)."""
        if self.next_due is not None:
            period = 1.0 / self.config.veh_state_rate
            self.next_due = max(self.next_due + period, now)

    def encode(self, scenario: Scenario, now: float) -> bytes:
        """The next message, with the scenario's signals at ``now``; raises
        :class:`~eyeq_spi.errors.LocalProtocolError` when it cannot be encoded (the rolling counter
        has moved on all the same)."""
        self.rolling = (self.rolling + 1) & 0xFFFF
        msg = self.codec.message(NAME)
        values = veh_state_values(self.codec.layout(msg).zero_values(), scenario.signals(now),
                                  now, sw_release(self.codec.sw), self.rolling)
        wire = self.codec.encode_dasp(msg.name, values, self.dasp_counter, self.e2e)
        self.dasp_counter = (self.dasp_counter + 1) & 0xFF
        return wire
