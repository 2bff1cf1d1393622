"""The one run summary (eyeq_spi/summary.py): the simulated EyeQ's side of a dropped or late MESP
reply, per-session totals, the text block."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from eyeq_spi.emulator import build, summary
from eyeq_spi.host.nvm import Nvm
from eyeq_spi.sim.config import SimConfig
from eyeq_spi.summary import KEYS, SimSessions, finish, format_summary, sim_summary


def _sim_view(cfg: SimConfig, tmp_path: Path) -> dict[str, Any]:
    """The sim's summary of a second ignition (the NVM already right: no EEPROM-driven reset)."""
    if not (tmp_path / "nvm.json").exists():
        build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)
    emu = build(sim_config=cfg, nvm=Nvm(tmp_path / "nvm.json"))
    emu.run_for(4.0)
    served = SimSessions()
    served.add(emu.sim, began=0.0, ended=4.0, link_lost=None)
    return sim_summary(emu.sim, served.sessions, elapsed=4.0, wall=1.0, cpu=1.0)


def test_the_sim_counts_a_dropped_reply_as_a_timeout(tmp_path: Path) -> None:
    s = _sim_view(SimConfig(drop_replies={"GetEyeQExtendedState": 1}), tmp_path)
    assert s["mesp"]["timeouts"] == 1 and not s["ok"] and "MESP timeouts" in str(s["problem"])
    assert list(s) == list(KEYS)


def test_the_sim_counts_a_reply_past_the_deadline_as_a_timeout(tmp_path: Path) -> None:
    s = _sim_view(SimConfig(delay_replies={"GetEyeQVersions": 0.7}), tmp_path)
    assert s["mesp"]["timeouts"] >= 1 and not s["ok"]
    assert _sim_view(SimConfig(delay_replies={"GetEyeQVersions": 0.1}), tmp_path)["ok"]


def test_sim_totals_are_the_sums_of_its_sessions(tmp_path: Path) -> None:
    served = SimSessions()
    for _ in range(2):
        emu = build(nvm=Nvm(tmp_path / "nvm.json"))
        emu.run_for(2.0)
        served.add(emu.sim, began=0.0, ended=2.0, link_lost=None)
    a, b = (dict(s) for s in served.sessions)
    s = sim_summary(emu.sim, served.sessions, elapsed=4.0, wall=1.0, cpu=1.0)
    assert s["connections"] == 2
    assert s["received"]["HOST_VEH_STATE_MSG"] == (a["received"]["HOST_VEH_STATE_MSG"]
                                                   + b["received"]["HOST_VEH_STATE_MSG"])
    assert s["ack_latency_ms"]["n"] == a["ack_latency_ms"]["n"] + b["ack_latency_ms"]["n"]
    assert "_ack_hist" not in s["sessions"][0]


def test_a_sim_powered_up_again_reports_each_session_alone(tmp_path: Path) -> None:
    """One SimulatedEyeQ serving two connections (a power-up each): the second session's
    counts are its own, not the run's so far."""
    build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)
    emu = build(nvm=Nvm(tmp_path / "nvm.json"))
    served = SimSessions()
    emu.run_for(2.0)
    first = dict(served.add(emu.sim, began=0.0, ended=2.0, link_lost=None))
    emu.run_for(2.0)  # the same EyeQ, the same host: two more seconds
    second = served.add(emu.sim, began=2.0, ended=4.0, link_lost=None)
    total = emu.sim.counters.received["HOST_VEH_STATE_MSG"]
    assert first["received"]["HOST_VEH_STATE_MSG"] + second["received"]["HOST_VEH_STATE_MSG"] \
        == total
    assert 0 < second["received"]["HOST_VEH_STATE_MSG"] < total
    assert second["boot"]["boots"] == 0 and second["eyeq_resets"] == 0
    s = sim_summary(emu.sim, served.sessions, elapsed=4.0, wall=1.0, cpu=1.0)
    assert s["received"]["HOST_VEH_STATE_MSG"] == total


def test_the_text_block_lists_received_and_sent_apart(tmp_path: Path) -> None:
    emu = build(nvm=Nvm(tmp_path / "nvm.json"))
    emu.run_for(2.0)
    text = format_summary(summary(emu))
    rx, tx = _topic(text, "received:"), _topic(text, "sent:")
    assert "HOST_VEH_STATE" not in rx and "HOST_VEH_STATE" in tx and "VIS_OBSTACLES" in rx


def _topic(text: str, head: str) -> str:
    """A topic of the text block with its continuation lines (folded at 80 columns)."""
    out: list[str] = []
    for line in text.splitlines():
        if line.startswith("  " + head) or (out and line.startswith("      ")):
            out.append(line)
        elif out:
            break
    return " ".join(x.strip() for x in out)


def test_the_text_block_fits_80_columns_and_folds_between_items(tmp_path: Path) -> None:
    emu = build(nvm=Nvm(tmp_path / "nvm.json"))
    emu.run_for(2.0)
    text = format_summary(summary(emu))
    assert max(len(line) for line in text.splitlines()) <= 80, text
    rx = _topic(text, "received:")
    assert len(rx) > 80  # folded, and every "NAME COUNT" item kept whole
    for item in rx.removeprefix("received: ").split(", "):
        name, count = item.split(" ")
        assert name.isupper() and count.isdigit(), item


def test_requests_abandoned_at_an_eyeq_reset_are_counted_apart_from_timeouts() -> None:
    """A reset EyeQ answers nothing it was asked before: the outstanding requests are
    ``abandoned`` (reported; the bring-up asks again), not timeouts (no deadline passed)."""
    from eyeq_spi.mesp.client import MespClient

    client = MespClient()
    client.request("GetEyeQVersions", now=0.0)
    client.request("GetEyeQExtendedState", now=0.0)
    client.cancel_all()
    assert client.counters.abandoned == 2 and client.counters.timeouts == 0
    client.handle_timer(10.0)  # nothing left to expire
    assert client.counters.timeouts == 0 and client.get_timer() is None


def test_running_vision_is_judged_once_for_every_run() -> None:
    """demo (the emulation) and host (eyeq_spi.live.drive) judge "reached and held" with the
    same RunningVision: entered, left, and judged again after a reconnection."""
    from types import SimpleNamespace

    from eyeq_spi.host.machine import HostState
    from eyeq_spi.summary import RunningVision

    watch = RunningVision()
    host: Any = SimpleNamespace(state=HostState.RUNNING_VISION)
    watch.update(host, 1.0)
    watch.update(host, 2.0)
    assert (watch.since, watch.left) == (1.0, [])
    host.state = next(s for s in HostState if s is not HostState.RUNNING_VISION)
    watch.update(host, 3.0)
    assert (watch.since, watch.left) == (None, [3.0])
    watch.reset()
    assert (watch.since, watch.left) == (None, [])
    emu = build(sim_config=SimConfig(reset_at=4.0), keep_rx_times=False)
    emu.run_for(8.0)
    assert emu.vision.left and emu.vision.left
    assert summary(emu)["running_vision_since"] == round(emu.vision.since or -1, 4)


def test_the_sim_text_names_the_main_state_the_json_gives_as_its_value(tmp_path: Path) -> None:
    """``sim``'s summary keeps Main_State as the JSON's ``0x02``; its text adds the name from
    specs/ (§7.1.5), as the host's text names its state."""
    s = _sim_view(SimConfig(), tmp_path)
    assert s["state"] == "0x02"
    assert format_summary(s).splitlines()[0].startswith("sim: OK - state 0x02 RUNNING_VISION, ")


def test_a_host_that_gave_up_names_why_before_the_link_it_then_lost() -> None:
    """A host stays connected after it gives up (§7.1.3 step 6); when the EyeQ then closes the
    link, the summary's problem is still why it gave up (link_lost says the rest)."""
    from eyeq_spi.summary import host_summary

    emu = build(sim_config=SimConfig(corrupt_eeprom_crc=True))
    emu.run_for(3.0)
    out = host_summary(emu.host, side="host", elapsed=3.0, wall=3.0, cpu=1.0,
                       running_since=None, left_running=[], link_lost="the peer left")
    assert out["state"] == "FAILED" and not out["ok"]
    assert "EEPROM" in out["problem"] and out["link_lost"] == "the peer left", out["problem"]
    emu = build()
    emu.run_for(0.05)  # still bringing the EyeQ up: a lost link is the problem
    out = host_summary(emu.host, side="host", elapsed=0.05, wall=0.05, cpu=0.05,
                       running_since=None, left_running=[], link_lost="the peer left")
    assert out["problem"] == "link lost"


def test_frames_a_leaving_host_left_in_flight_are_no_loss_of_the_next_session(
        tmp_path: Path) -> None:
    """``sim`` powers the EyeQ up for each host; that reset (L10) drops what the link still had
    in flight for the host that left, counted as send failures. Those belong to no session
    (the last one ended when its host left): the next host's session starts clean, and the
    busyFrames gauge is its value, never a difference."""
    build(nvm=Nvm(tmp_path / "nvm.json")).run_for(3.0)  # the first ignition writes the NVM
    emu = build(nvm=Nvm(tmp_path / "nvm.json"))
    emu.run_for(2.0)
    link = emu.sim.conn.link
    while not link._inflight:  # the host leaves in the middle of a frame
        emu.run_for(0.0002)
    served = SimSessions()
    served.add(emu.sim, began=0.0, ended=emu.runner.now, link_lost="the peer left")
    emu.sim.power_up(emu.runner.now)  # the next host connects
    assert link.counters.sendFailedErrorCounter > 0  # the reset dropped the frames in flight
    served.begin(emu.sim)
    second = served.add(emu.sim, began=emu.runner.now, ended=emu.runner.now, link_lost=None)
    assert second["link"]["sendFailedErrorCounter"] == 0 and second["ok"], second["problem"]
    assert second["link"]["busyFrames"] == link.counters.busyFrames >= 0


def test_a_lost_frame_is_named_before_what_it_caused() -> None:
    """The figures of a live run that lost one frame: the transfer aborted, its message left a
    DASP gap, the next obstacles message's 16 structures were rejected (D5). The problem names
    the loss first and says the E2E errors followed it; E2E errors alone stay plain."""
    base = {"link": {"sendFailedErrorCounter": 0}, "mesp": {"timeouts": 0},
            "stale_streams": []}
    lost = finish({**base, "transport_aborts": {"interleaved": 1}, "dasp_counter_gaps": 1,
                   "e2e_errors": 16}, None)
    assert lost["problem"] == ("transport aborts {'interleaved': 1}; 1 DASP counter gaps; "
                               "16 E2E errors (after the gaps: D5 rejects a structure whose "
                               "rolling counter jumped)"), lost["problem"]
    corrupt = finish({**base, "transport_aborts": {}, "dasp_counter_gaps": 0,
                      "e2e_errors": 2}, None)
    assert corrupt["problem"] == "2 E2E errors" and not corrupt["ok"]


def test_frames_sent_to_a_host_that_fell_silent_are_what_it_left(tmp_path: Path) -> None:
    """SPI lines have no hang-up: a host that goes away falls silent, and the EyeQ keeps
    sending until the silence says the link is lost. The frames that failed after the host
    was last heard went to nobody: they are what the host left, not send failures of the
    session (which ran clean)."""
    emu = build(nvm=Nvm(tmp_path / "nvm.json"))
    emu.run_for(3.0)
    sim, now = emu.sim, emu.runner.now
    heard = sim.conn.link.counters.sendFailedErrorCounter
    end = now + 1.0
    while now < end:  # the host is gone: the EyeQ's frames are never ACKed
        timer = sim.get_timer()
        now = min(end, timer if timer is not None else end)
        sim.handle_timer(now)
        sim.data_to_send(now)
        now += 1e-4
    failed = sim.conn.link.counters.sendFailedErrorCounter - heard
    assert failed > 10
    session = SimSessions().add(sim, began=0.0, ended=now, link_lost="the peer fell silent",
                                failed_when_heard=heard)
    assert session["link"]["sendFailedErrorCounter"] == heard, session["link"]
    assert session["left_at_link_loss"]["frames"] >= failed
    assert session["ok"] == (heard == 0), session["problem"]
    unheard = SimSessions().add(sim, began=0.0, ended=now, link_lost="the peer fell silent")
    assert unheard["link"]["sendFailedErrorCounter"] == heard + failed
    assert not unheard["ok"] and "send failures" in unheard["problem"]
