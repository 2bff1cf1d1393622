"""``can decode --bus INTERFACE:CHANNEL``: a live python-can bus decoded like a log (virtual bus
always; socketcan on vcan where the OS allows)."""

from __future__ import annotations

import json
import random
import threading
from typing import Any

import pytest

can = pytest.importorskip("can", reason="needs the [can] extra (python-can)")
pytest.importorskip("cantools", reason="needs the [can] extra (cantools)")

from eyeq_spi.can.decode import CanDecoder  # noqa: E402
from eyeq_spi.can.logs import open_bus, read_bus  # noqa: E402
from eyeq_spi.cli import main  # noqa: E402
from tests import camera_can  # noqa: E402
from tests.test_can_gateway import _vcan  # noqa: E402
from tests.waiting import wait_until  # noqa: E402


def cycle_messages(cycles: int = 3) -> list[Any]:
    rng = random.Random(2)
    return [can.Message(arbitration_id=fid, data=data, is_extended_id=False)
            for n in range(cycles) for fid, data in camera_can.camera_cycle(n, n * 0.078, rng)]


def test_read_bus_on_a_virtual_bus_stops_at_count_and_on_its_clock() -> None:
    rx = open_bus("virtual:eyeq-test-read-bus")
    tx = can.Bus(interface="virtual", channel="eyeq-test-read-bus")
    try:
        sent = cycle_messages()
        for m in sent:
            tx.send(m)
        got = list(read_bus(rx, count=len(sent) - 1))
        assert [m.arbitration_id for m in got] == [m.arbitration_id for m in sent[:-1]]
        recs = [CanDecoder("extlog2").decode(m, i) for i, m in enumerate(got)]
        assert all(not r["errors"] for r in recs)
        assert any(r["short_dlc"] for r in recs)
        # nothing more arrives: the injected clock ends the read, no waiting on the wall
        ticks = iter([0.0, 0.0, 0.3, 0.6, 0.9, 1.2])
        rest = list(read_bus(rx, duration=1.0, now=lambda: next(ticks), poll=0.0))
        assert [m.arbitration_id for m in rest] == [sent[-1].arbitration_id]
    finally:
        tx.shutdown()
        rx.shutdown()


def _send_when_listened(channel: str, msgs: list[Any]) -> threading.Thread:
    """Send ``msgs`` on a virtual channel once a second bus (the CLI's) has joined it."""
    from can.interfaces import virtual

    tx = can.Bus(interface="virtual", channel=channel)

    def run() -> None:
        try:
            wait_until(lambda: len(virtual.channels.get(channel, [])) >= 2, 20.0,
                       "the CLI's bus joined the channel")
            for m in msgs:
                tx.send(m)
        finally:
            tx.shutdown()

    th = threading.Thread(target=run, daemon=True)
    th.start()
    return th


def test_cli_decodes_a_virtual_bus(capsys: pytest.CaptureFixture[str]) -> None:
    msgs = cycle_messages()
    th = _send_when_listened("eyeq-test-cli-bus", msgs)
    capsys.readouterr()
    assert main(["can", "decode", "--bus", "virtual:eyeq-test-cli-bus", "--count",
                 str(len(msgs)), "--json"]) == 0
    th.join(5)
    recs = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert len(recs) == len(msgs) and all(not r["errors"] for r in recs)
    assert {r["name"] for r in recs} >= {"Car_Info", "Fixed_FOE", "LKA_Left_Lane_B"}
    th = _send_when_listened("eyeq-test-cli-bus-stats", msgs)
    assert main(["can", "decode", "--bus", "virtual:eyeq-test-cli-bus-stats", "--count",
                 str(len(msgs)), "--stats", "--json"]) == 0
    th.join(5)
    s = json.loads(capsys.readouterr().out)
    assert s["frames"] == len(msgs) and s["short_dlc"] == 12


@pytest.mark.parametrize(("argv", "needle"), [
    (["can", "decode"], "one of them"),
    (["can", "decode", "x.blf", "--bus", "virtual:x"], "one of them"),
    (["can", "decode", "x.blf", "--count", "3"], "apply to --bus"),
    (["can", "decode", "--bus", "virtual"], "INTERFACE:CHANNEL"),
    (["can", "decode", "--bus", "nosuchinterface:x"], "cannot open CAN bus"),
])
def test_bus_usage_errors_are_one_line(argv: list[str], needle: str,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def test_socketcan_vcan_bus() -> None:
    dev = _vcan()
    try:
        tx = can.Bus(interface="socketcan", channel=dev)
    except (OSError, can.CanError) as exc:
        pytest.skip(f"socketcan on {dev} cannot be opened: {exc}")
    rx = open_bus(f"socketcan:{dev}")
    try:
        sent = cycle_messages(1)
        for m in sent:
            tx.send(m)
        got = list(read_bus(rx, count=len(sent), duration=5.0))
        assert [m.arbitration_id for m in got] == [m.arbitration_id for m in sent]
    finally:
        tx.shutdown()
        rx.shutdown()


def test_monitor_view_of_a_can_bus_lists_ids_cycles_and_signals() -> None:
    pytest.importorskip("rich", reason="the monitor needs rich")
    from eyeq_spi.monitor.can_bus import CanBusView

    view = CanBusView("extlog2", "virtual:test")
    rng = random.Random(3)
    for n in range(4):
        for fid, data in camera_can.camera_cycle(n, 0.0, rng):
            view.add(can.Message(timestamp=100 + n * 0.078, arbitration_id=fid, data=data,
                                 is_extended_id=False, channel=1), n * 0.078)
    view.add(can.Message(timestamp=101, arbitration_id=0x738, data=bytes(7),
                         is_extended_id=False, channel=1), 1.0)
    text = [t.plain for t in view.lines(width=200)]
    assert "errors 1" in text[0] and len(text) == 2 + len(view.rows)
    foe = next(t for t in text if " 650 Fixed_FOE" in t)
    assert "Fixed_Yaw=40" in foe and " 78 " in foe and " 66 " in foe  # cycle, spec
    assert any("Obstacle_Status" in t and "DLC 7, spec 6" in t for t in text)
    assert len(view.lines(width=80, height=10)) == 10  # a short terminal: cropped, says so


def test_monitor_cli_shows_a_virtual_bus(tmp_path: Any,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("rich", reason="the monitor needs rich")
    msgs = cycle_messages()
    th = _send_when_listened("eyeq-test-monitor-bus", msgs)
    shot = tmp_path / "can.txt"
    capsys.readouterr()
    assert main(["monitor", "--can-bus", "virtual:eyeq-test-monitor-bus", "--duration", "2.5",
                 "--screenshot", str(shot)]) == 0
    th.join(5)
    out = capsys.readouterr().out
    assert "Car_Info" in out and "LKA_Left_Lane_B" in out and "errors 0" in out
    assert "Fixed_FOE" in shot.read_text()
