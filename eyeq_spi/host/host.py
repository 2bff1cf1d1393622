"""The Aurix host emulator: brings an EyeQ4 up and runs it in vision mode (and TAC/SPC/DV) over
the real link and transport. Sans-IO; the state machine is the table in ``machine.py``, run with
its entry actions by the base class in ``bringup.py``; this module adds the node interface, the
receive path, stale detection and HOST_VEH_STATE_MSG.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

from eyeq_spi.catalog.messages import sw_release
from eyeq_spi.catalog.tables import alignment_nvm
from eyeq_spi.codec.e2e import E2EState
from eyeq_spi.codec.init_params import init_message
from eyeq_spi.codec.message import DecodedMessage
from eyeq_spi.errors import CodecError, EyeqError, LocalProtocolError, SpecError
from eyeq_spi.host import calibration, init_seq
from eyeq_spi.host.bringup import SWITCH_APP, HostBringUp, ResetLine, Subscriber
from eyeq_spi.host.config import (
    APP_IDS,
    FATAL_INTRINSIC,
    PENDING,
    STAGE_OF,
    STALE_CHECK,
    E,
    HostConfig,
    HostCounters,
    S,
    Transition,
)
from eyeq_spi.host.machine import next_state
from eyeq_spi.host.scenario import veh_state_values
from eyeq_spi.host.veh_state_fast import VehStatePacker
from eyeq_spi.link.events import Resynchronised
from eyeq_spi.mesp.client import MespCompleted, MespFailed
from eyeq_spi.transport.events import MessageReceived
from eyeq_spi.twins import exact

__all__ = ["SWITCH_APP", "HostConfig", "HostCounters", "HostEmulator", "ResetLine", "Subscriber",
           "Transition"]


class HostEmulator(HostBringUp):
    """The host emulator as a sans-IO node: the public API, the receive path, stale detection
    and HOST_VEH_STATE_MSG. Its state and bring-up are :class:`HostBringUp`."""

    # -- public API -------------------------------------------------------------------------
    def start(self, now: float) -> None:
        """Ignition on: count the cycle, wait for the EyeQ's boot status."""
        self._started = True
        self.nvm.data.ignition_cycles += 1
        self._enter(S.POWER_UP, now)

    def subscribe(self, callback: Subscriber) -> None:
        self._subscribers.append(callback)

    def messages(self) -> AsyncIterator[DecodedMessage]:
        """Async iterator over delivered messages (one queue per iterator): the asyncio
        adapter ``runner/aio.py``, loaded only when asked for."""
        from eyeq_spi.runner.aio import message_stream

        return message_stream(self.subscribe)

    def switch_mode(self, mode: str, now: float) -> None:
        """Go to TAC, SPC or DV, or back to VISION (§6 flow step 16)."""
        mode = mode.upper()
        if mode not in APP_IDS:
            raise LocalProtocolError(f"unknown mode {mode!r}: use VISION, TAC, SPC or DV")
        if self.state not in (S.RUNNING_VISION, S.RUNNING_TAC, S.RUNNING_SPC, S.DV):
            raise LocalProtocolError(f"cannot switch mode in state {self.state.value}")
        stage = STAGE_OF.get(mode)
        if stage is not None:
            try:
                init_message(stage, self.sw, self.codec.cat)
            except (SpecError, CodecError) as exc:
                # §7.1.1.7: the mode needs its init message; this release has no table for it
                raise LocalProtocolError(
                    f"{mode} is not available for SW {self.sw}: {exc}") from None
        self._target_mode = mode
        self._fire(E.SWITCH, now, mode)

    def link_restarted(self, now: float) -> None:
        """The byte stream to the EyeQ was re-established (a new connection is a power-up):
        restart our SPI driver and run the bring-up again. A host that had given up (FAILED,
        BOOT_FAILED) stayed quiet on the old connection; the new one is its next ignition
        cycle (:meth:`_next_ignition_cycle`)."""
        self._cancel_requests()
        self._restart_driver()
        if self.state in (S.FAILED, S.BOOT_FAILED):
            self._next_ignition_cycle(now, "new connection after the host gave up")
        else:  # every other state takes an EyeQ reset (machine.py)
            self._fire(E.EYEQ_RESET, now, "link re-established")

    def _next_ignition_cycle(self, now: float, why: str) -> None:
        """Ignition off and on after the host gave up (FAILED, BOOT_FAILED; §7.1.3 step 6: the
        unit is failed for this ignition cycle): what a new host with the same NVM would be.
        The per-cycle state starts afresh (boot strikes, EyeQ resets for the EEPROM, Get EyeQ
        Versions asked once per ignition cycle, the problem, our DASP counters); the run's
        counters and transitions go on."""
        self._cancel_requests()
        self._versions_asked = self._versions_ok = False
        self._strikes = self._bringups = 0
        self._target_mode = "VISION"
        self.problem = None
        self.calibration_result = None
        self._tx_e2e = E2EState()
        self._dasp_counter = self._rolling = 0
        self.nvm.data.ignition_cycles += 1
        self._fire(E.IGNITION, now, why)

    def warm_up(self) -> None:
        """Decode one message of each kind the EyeQ sends and encode HOST_VEH_STATE once, so
        that no first-time codec build delays an ACK in real time."""
        e2e = E2EState()
        for m in self.codec.cat.messages:
            if m.protocol == "DASP" and m.direction == "e2h" and m.exists_in(self.sw):
                lay = self.codec.layout(m)
                self.codec.decode(self.codec.encode_dasp(m.name, lay.zero_values(), 0, e2e),
                                  E2EState())
        msg = self.codec.message("HOST_VEH_STATE_MSG")
        self.codec.encode_dasp(msg.name, self.codec.layout(msg).zero_values(), 0, E2EState())
        self.mesp.codec.warm_up()  # MESP requests we send, replies we read
        self.codec.mesp.warm_up()

    # -- node interface ---------------------------------------------------------------------
    def receive_data(self, transfer: bytes, now: float) -> None:
        self.now = now
        self.conn.receive_data(transfer, now)
        self._pump(now)

    def data_to_send(self, now: float) -> list[bytes]:
        self._flush_mesp(now)
        return self.conn.data_to_send(now)

    def get_timer(self) -> float | None:
        # asked after every event (runner/virtual.py): no temporary lists here
        best = self.conn.get_timer()
        if self.mesp.outstanding:
            t = self.mesp.get_timer()
            if t is not None and (best is None or t < best):
                best = t
        t = self._boot_deadline
        if t is not None and (best is None or t < best):
            best = t
        t = self._next_poll
        if t is not None and (best is None or t < best):
            best = t
        t = self._veh_next
        if t is not None and (best is None or t < best):
            best = t
        if self.state is S.RUNNING_VISION and self._last_rx:
            t = self._next_stale_check
            if best is None or t < best:
                best = t
        return best

    def handle_timer(self, now: float) -> None:
        self.now = now
        self.conn.handle_timer(now)
        self.mesp.handle_timer(now)
        if self._boot_deadline is not None and now >= self._boot_deadline:
            self._boot_deadline = None
            self._boot_failed(now, "no boot status within the timeout")
        if self._next_poll is not None and now >= self._next_poll and not self._poll_busy:
            self._next_poll = None
            self._poll_busy = True
            self.mesp.request("GetEyeQExtendedState", now=now)
        if self._veh_next is not None and now >= self._veh_next:
            self._send_veh_state(now)
            if self._veh_next is not None:  # None: the message could not be encoded (problem)
                period = 1.0 / self.config.veh_state_rate
                self._veh_next = max(self._veh_next + period, now)
        if self.state is S.RUNNING_VISION and now >= self._next_stale_check:
            self._next_stale_check = now + STALE_CHECK
            self._check_stale(now)
        self._pump(now)

    # -- receive ----------------------------------------------------------------------------
    def _pump(self, now: float) -> None:
        while (ev := self.conn.next_event()) is not None:
            if isinstance(ev, MessageReceived):
                self._on_message(ev.data, now)
            elif isinstance(ev, Resynchronised):
                self._on_link_resync(ev, now)
        while (mev := self.mesp.next_event()) is not None:
            if isinstance(mev, MespCompleted) and mev.reply.function == "GetEyeQExtendedState":
                self._poll_busy = False
                self._on_state_reply(mev.reply)
            elif isinstance(mev, MespFailed) and mev.failure.function == "GetEyeQExtendedState":
                self._poll_busy = False
                if self._next_poll is None and self.state in (
                        S.WAIT_PENDING, S.WAIT_RUNNING, S.WAIT_MODE_PENDING, S.WAIT_MODE_RUNNING):
                    self._next_poll = now + self.config.poll_interval
        self._flush_mesp(now)

    def _on_message(self, data: bytes, now: float) -> None:
        if self.mesp.receive_message(data, now):
            return
        dasp = data[:1] == b"\x65"
        # field values only when someone reads them: subscribers (async iterators too), a
        # TAC/SPC result; E2E, counters and lengths are checked either way
        fields = not dasp or bool(self._subscribers) \
            or self.state in (S.RUNNING_TAC, S.RUNNING_SPC)
        out = self.codec.decode(data, self._e2e if dasp else None, fields=fields)
        name = out.name or out.protocol
        self.counters.received[name] += 1
        if self.keep_rx_times:
            self.counters.rx_times.setdefault(name, []).append(now)
        if out.protocol == "BOOT":
            self._on_boot(out, now)
        elif out.protocol == "DIAG":
            self._on_diag(out, now)
        elif out.protocol == "DASP":
            self._on_dasp(out, data, now)
        else:
            self.counters.decode_errors += 1

    def _on_boot(self, out: DecodedMessage, now: float) -> None:
        if out.errors:
            self.counters.decode_errors += 1
            return
        f = out.fields
        self.boot_info = init_seq.boot_info(f)
        if self.state is not S.POWER_UP:
            # a boot status we did not ask for: the EyeQ reset (by itself, or on our soft
            # reset); our link to it starts over in both directions (L10), and no request
            # from before the reset will be answered
            self.conn.restart()
            self._cancel_requests()
            self.counters.eyeq_resets += 1
            self._fire(E.EYEQ_RESET, now, "unexpected boot status")
        self._boot_deadline = None
        if f["TestResults"]:
            self._boot_failed(now, f"boot test bits 0x{f['TestResults']:04X}")
        else:
            self._strikes = 0
            self._fire(E.BOOT_OK, now)

    def _boot_failed(self, now: float, why: str) -> None:
        self._strikes += 1
        self.counters.boot_failures += 1
        if self._strikes >= self.config.boot_strikes:
            self.problem = f"EyeQ boot failed {self._strikes} times in a row ({why})"
            self._fire(E.BOOT_STRIKE_OUT, now, self.problem)
            return
        self._fire(E.BOOT_BAD, now, why)
        self._reset_eyeq(now)

    def _diag_event(self, out: DecodedMessage) -> str | None:
        """What a good 0x41 starts (before the host keeps it as ``last_diag``):
        ``"fatal_22"``, ``"fatal"``, ``"went_back"``, or None (it is only kept)."""
        main, fatal = out.fields["Main_State"], out.fields["Fatal_Error"]
        before_vision = self.state in (S.WAIT_PENDING, S.INIT, S.WAIT_RUNNING)
        if fatal == FATAL_INTRINSIC and before_vision:
            return "fatal_22"
        if fatal and self.state not in (S.FATAL, S.READ_EEPROM, S.FAILED, S.POWER_UP):
            return "fatal"
        # A running EyeQ never reports boot or pending again without a reset. Compare with the
        # mode, not with the previous 0x41: the host can reach Running Vision by a Get State
        # reply before any 0x41 has reported it (found by the reset campaign, faults/resets.py).
        if (self.state in (S.RUNNING_VISION, S.RUNNING_TAC, S.RUNNING_SPC)
                and main in (0, PENDING) and self.last_diag.get("Main_State") is not None):
            return "went_back"
        return None

    def _on_diag(self, out: DecodedMessage, now: float) -> None:
        if out.errors:
            self.counters.decode_errors += 1
            return
        event = self._diag_event(out)
        self.last_diag = out.fields
        if event == "fatal_22":
            self._fire(E.FATAL_22, now, "0x41 Fatal_Error 22")
        elif event == "fatal":
            self.problem = f"EyeQ fatal error {out.fields['Fatal_Error']}"
            self._fire(E.FATAL, now, self.problem)
        elif event == "went_back":
            self.counters.eyeq_resets += 1
            self._fire(E.EYEQ_RESET, now,
                       f"0x41 Main_State went back to {out.fields['Main_State']}")
            self._enter_after_app_restart(now)

    def _on_link_resync(self, ev: Resynchronised, now: float) -> None:
        """The EyeQ's link started over (L6/L6a): NUM went back, so the EyeQ reset by itself.
        Its boot status was probably lost to out-of-window NAKs, so do not wait for it."""
        if ev.cause == "peer_restart" or (
                self._switch_at is not None and now - self._switch_at <= self.mesp.deadline):
            # L10: the EyeQ took our Switch EyeQ Application and started its link afresh, as
            # we did ours: the switch, not a reset of its own
            self._switch_at = None
            return
        if self.state in (S.POWER_UP, S.FAILED, S.BOOT_FAILED):
            return  # a boot status is awaited anyway (with its timeout), or we gave up
        self.counters.eyeq_resets += 1
        if next_state(self.state, E.EYEQ_RESET) is None:
            return
        self._fire(E.EYEQ_RESET, now, f"EyeQ link restarted at NUM {ev.num} ({ev.cause})")
        if self.reset_line is not None:
            # a clean power-up: both SPI drivers start over, the boot status arrives in window
            self._reset_eyeq(now, bringup=False)
        else:
            self._cancel_requests()
            self.conn.restart()  # L10: our transmitter numbers from 0 again as well
            self._enter_after_app_restart(now)

    def _enter_after_app_restart(self, now: float) -> None:
        # the application restarted without a boot status: skip the boot wait
        if self.state is S.POWER_UP:
            self._boot_deadline = None
            self._fire(E.BOOT_OK, now, "application restarted")

    def _on_dasp(self, out: DecodedMessage, data: bytes, now: float) -> None:
        data_id = out.header.get("data_id")
        if data_id is not None and self._rx_counters.check(data_id, out.header["counter"]) \
                is not None:
            self.counters.dasp_counter_gaps += 1
        e2e = [e for e in out.errors if e.startswith("E2E")]
        if e2e:
            self.counters.e2e_errors += len(e2e)
        if out.errors:
            if not e2e:
                self.counters.decode_errors += 1
            return  # a rejected structure is never delivered (D5)
        if out.name is not None:
            self._last_rx[out.name] = now
            self._stale.discard(out.name)
        if self.state is S.RUNNING_TAC and out.name == "EYEQ_TAC_CAL_MSG":
            self._on_cal_result("TAC", out.fields["tacCalParams"], now)
        elif self.state is S.RUNNING_SPC and out.name == "EYEQ_DYNAMIC_CAL_MSG":
            self._on_cal_result("SPC", out.fields["dynamicCalParams"], now)
        if self.state in (S.RUNNING_VISION, S.RUNNING_TAC, S.RUNNING_SPC):
            self._deliver(out)

    def _on_cal_result(self, mode: str, cal: dict[str, Any], now: float) -> None:
        if self.calibration_result is not None:
            return
        ok = calibration.outcome(self.codec.cat, self.sw, mode, cal)
        if ok is None:
            return  # still running
        self.calibration_result = {"mode": mode, "ok": ok, "time": now, **{
            k: cal[k] for k in ("distYaw", "distPitch", "roll", "phYaw", "phPitch") if k in cal}}
        if ok:  # §21: "update ... only when TAC, SPC or Autofix is successfully completed"
            self.nvm.data.alignment = alignment_nvm().apply(mode, self.nvm.data.alignment, cal)
            self.nvm.save()

    def _deliver(self, out: DecodedMessage) -> None:
        for cb in self._subscribers:
            cb(out)

    # -- stale detection --------------------------------------------------------------------
    def _check_stale(self, now: float) -> None:
        for name, t in self._last_rx.items():
            limit = self._stale_limits.get(name)
            if limit is not None and name not in self._stale and now - t > limit:
                self._stale.add(name)
                self.counters.stale_events[name] += 1

    @property
    def stale_streams(self) -> set[str]:
        return set(self._stale)

    # -- transmit ---------------------------------------------------------------------------
    def _send_veh_state(self, now: float) -> None:
        self._rolling = (self._rolling + 1) & 0xFFFF
        signals = self.scenario.signals(now)
        # the fast twin (host/veh_state_fast.py) where it can say, else the dict path
        packer = None if exact() else self._veh_packer()
        wire = None if packer is None else packer.encode(
            signals, now, self._rolling, self._dasp_counter, self._tx_e2e)
        if wire is None:
            msg = self.codec.message("HOST_VEH_STATE_MSG")
            values = veh_state_values(self.codec.layout(msg).zero_values(), signals, now,
                                      sw_release(self.sw), self._rolling)
            try:
                wire = self.codec.encode_dasp(msg.name, values, self._dasp_counter,
                                              self._tx_e2e)
            except CodecError as exc:
                self.problem = f"HOST_VEH_STATE_MSG cannot be encoded: {exc}"
                self._veh_next = None
                return
        self._dasp_counter = (self._dasp_counter + 1) & 0xFF
        self.conn.send(wire, now)
        self.counters.sent["HOST_VEH_STATE_MSG"] += 1
        if self.keep_rx_times:
            self.counters.tx_times.append(now)

    def _veh_packer(self) -> VehStatePacker | None:
        """The template of HOST_VEH_STATE_MSG for our codec (built on first use), None where
        it cannot be built (the dict path then encodes, or reports why not)."""
        built = self._veh_packed
        if built is None or built[0] is not self.codec:
            try:
                packer: VehStatePacker | None = VehStatePacker(self.codec, sw_release(self.sw))
            except (EyeqError, ValueError, KeyError):
                packer = None
            built = self._veh_packed = (self.codec, packer)
        return built[1]
