"""The monitor in an 80x24 terminal: panels fold, nothing essential is cut; times since the
start; rates judged from a stream's first message against its nominal rate."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

pytest.importorskip("rich", reason="the monitor extra (rich) is not installed")

from eyeq_spi.catalog.messages import catalog
from eyeq_spi.cli import main
from eyeq_spi.emulator import build
from eyeq_spi.monitor.model import RateMeter
from eyeq_spi.monitor.sources import ReplaySource, _HostView
from eyeq_spi.monitor.view import screen_lines
from tests.test_monitor import _drain, _run_in_pty


@pytest.fixture(scope="module")
def busy_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """2 s of the emulator with 10 objects and 5 signs; SRP stops at 1.2 s."""
    path = tmp_path_factory.mktemp("compact") / "busy.pcapng"
    main(["demo", "--virtual-time", "--duration", "2", "--objects", "10", "--signs", "5",
          "--stop-dasp", "EYEQ_VIS_SRP_MSG@1.2", "--capture", str(path), "--json"])
    return path


def test_80x24_folds_the_panels_and_keeps_what_matters(busy_capture: Path) -> None:
    snap = _drain(ReplaySource(str(busy_capture), speed=0))
    lines = [t.plain for t in screen_lines(snap, 80, 24)]
    text = "\n".join(lines)
    assert len(lines) <= 23 and max(len(line) for line in lines) <= 80, text
    assert lines[0].startswith("replay busy.pcapng") and "RUNNING_VISION" in lines[0]
    assert "t 1.90 s" in lines[0]  # seconds since the start
    for key, value in {**snap.link, **snap.errors}.items():  # every counter, with its value
        assert f"{key} {value}" in text, key
    assert "stale streams: VIS_SRP" in text
    assert re.search(r"VIS_SRP\s+[\d.]+\s+18 stopped", text)
    for row in snap.rates:  # every stream has its rate line
        assert row.name.removeprefix("EYEQ_").removesuffix("_MSG")[:17] in text
    assert re.search(r"objects 10: nearest \d+ shown, \d+ more", text)
    last = snap.transitions[-1]
    assert f"{last[0]:8.3f}  {last[1]} --{last[2]}--> {last[3]}" in text
    wide = [t.plain for t in screen_lines(snap, 160, 80)]  # room: the full screen
    assert any(line.startswith("objects (10)") for line in wide)


def test_the_transitions_panel_counts_every_transition_it_does_not_show() -> None:
    """The views keep the last few transitions; their titles say how many there were in all
    (an EyeQ that reset three times has more than fit), on the small screen and the wide one."""
    from eyeq_spi.monitor.model import Snapshot

    trans = [(float(k), f"S{k}", "E", f"S{k + 1}") for k in range(11, 19)]
    snap = Snapshot("test", 20.0, "host state", "S19", trans, transitions_seen=19)
    small = "\n".join(t.plain for t in screen_lines(snap, 80, 24))
    assert re.search(r"transitions \((s since the start, )?last \d+ of 19\)", small), small
    wide = "\n".join(t.plain for t in screen_lines(snap, 160, 80))
    assert "transitions (last 6 of 19)" in wide, wide
    few = Snapshot("test", 20.0, "host state", "S2", trans[:2], transitions_seen=2)
    assert "of 2)" not in "\n".join(t.plain for t in screen_lines(few, 160, 80))


def test_transitions_are_dated_from_the_start() -> None:
    """The host emulator on the real-time runner keeps monotonic clock readings: the view
    shows them from its origin (the runner's clock when the monitor started)."""
    emu = build(keep_rx_times=False)
    view = _HostView(emu.host, "host", origin=0.25)
    emu.run_for(1.0)
    snap = view.snapshot(1.0 - 0.25, False)
    raw = [t.time for t in emu.host.transitions[-8:]]
    assert [t[0] for t in snap.transitions] == pytest.approx([t - 0.25 for t in raw])


def test_a_stream_that_began_late_is_not_low() -> None:
    """Rates count from a stream's first message: 1 s after the bring-up an 18 Hz stream is
    18 Hz and ok, not 9 Hz "low" over a 2 s window that holds the bring-up."""
    meter = RateMeter(catalog())
    name = "EYEQ_VIS_OBSTACLES_MSG"
    arrivals = [(0.5 + k / 18, name) for k in range(19)] + [
        (k * 0.015, "HOST_VEH_STATE_MSG") for k in range(101)]
    counts: dict[str, int] = {}
    for t, msg in sorted(arrivals):
        meter.arrived(msg, t)
        counts[msg] = counts.get(msg, 0) + 1
    meter.tick(1.5, counts)
    row = {r.name: r for r in meter.rows()}[name]
    assert row.hz == pytest.approx(18, abs=0.01) and row.status == "ok"


def test_a_fresh_stream_is_not_judged_yet() -> None:
    meter = RateMeter(catalog())
    name = "EYEQ_VIS_OBSTACLES_MSG"
    for k in range(5):
        meter.arrived(name, 0.05 + k / 18)
    meter.tick(0.3, {name: 5})
    assert {r.name: r for r in meter.rows()}[name].status == "-"


def test_demo_in_an_80x24_pseudo_terminal() -> None:
    if not sys.platform.startswith("linux"):
        pytest.skip("needs a Linux pty")
    pyte = pytest.importorskip("pyte", reason="pyte reads the terminal screen (test extra)")
    returncode, chunks = _run_in_pty(["--demo", "--virtual-time", "--duration", "3",
                                      "--objects", "10", "--signs", "3"], 24, 80)
    screen = pyte.Screen(80, 24)
    pyte.ByteStream(screen).feed(b"".join(c for _, c in chunks))
    assert returncode == 0
    lines = [line.rstrip() for line in screen.display]
    text = "\n".join(lines)
    assert lines[0].startswith("demo (virtual time)") and "finished" in lines[0], text
    assert "MESP timeouts 0" in text and "stale streams: none" in text
    assert re.search(r"objects 10", text) and "transitions" in text
    assert re.search(r"VIS_OBSTACLES\s+1[78]\.\d\s+18 ok", text), text
    assert "--RUNNING_VISION--> RUNNING_VISION" in text


def _with_objects() -> object:
    from eyeq_spi.monitor.model import Snapshot
    from eyeq_spi.plot.perceived import Scene, SceneObject

    def obj(oid: int, long: float, ttc: float) -> SceneObject:
        return SceneObject(id=oid, cls=0, cls_name="car", long=long, lat=0.0, width=1.8,
                           length=4.5, heading=0.0, v_long=10.0, v_lat=0.0, cipv=False, ttc=ttc)

    # behind the car (a TTC there is not a collision ahead), ahead with "none" (7 s, §13.2.2),
    # ahead and closing
    scene = Scene(objects=[obj(1, -4.0, 2.5), obj(2, 30.0, 7.0), obj(3, 20.0, 3.2)])
    return Snapshot("test", 5.0, "host state", "RUNNING_VISION", scene=scene)


@pytest.mark.parametrize("size", [(80, 24), (160, 80)])
def test_ttc_only_for_objects_ahead_and_closing(size: tuple[int, int]) -> None:
    from eyeq_spi.plot.perceived import NO_TTC

    text = "\n".join(t.plain for t in screen_lines(_with_objects(), *size))  # type: ignore[arg-type]
    rows = {m.group(1): m.group(0) for m in re.finditer(r"^\s*(\d)\s+car\b.*$", text, re.M)}
    if size == (80, 24):  # two objects a line: split the line into its cells
        rows = {}
        for line in text.splitlines():
            for m in re.finditer(r"(\d)\s+car\s+\S+\s+\S+\s+\S+\s+(\S+)", line):
                rows[m.group(1)] = m.group(0)
    assert set(rows) == {"1", "2", "3"}, text
    assert rows["1"].split()[-1] == NO_TTC and rows["2"].split()[-1] == NO_TTC, text
    assert rows["3"].split()[-1] == "3.2", text
    assert "7.0" not in text and "2.5" not in text


def test_a_screen_as_tall_as_the_terminal_keeps_its_title() -> None:
    """The terminal's last row is the cursor's: a screen exactly as tall as the terminal
    scrolls its first line away, so it is folded to one row less."""
    snap = _with_objects()
    full = screen_lines(snap, 160)  # type: ignore[arg-type]
    for rows in (len(full), len(full) + 1):
        lines = screen_lines(snap, 160, rows)  # type: ignore[arg-type]
        assert len(lines) <= rows - 1, (rows, len(lines))
        assert lines[0].plain.startswith(full[0].plain[:20])


def test_help_asks_for_no_extra(capsys: pytest.CaptureFixture[str]) -> None:
    """rich is part of the base install: the help does not send the user to an extra."""
    with pytest.raises(SystemExit):
        main(["monitor", "--help"])
    assert "[monitor]" not in capsys.readouterr().out
