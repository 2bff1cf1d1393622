"""The dissect pipeline (eyeq_spi.dissect.pipeline) and the readers of captures that go through
it: plot, monitor, export and replay read every input format dissect reads, and say what
they said for the pcapng capture."""

from __future__ import annotations

import dataclasses
import io
import json
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi import twins
from eyeq_spi.capture.pcapng_io import Transfer, read_pcapng
from eyeq_spi.cli import main
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.dissect import pipeline
from eyeq_spi.dissect.pipeline import DissectConfig, dissect_files, open_capture_file
from eyeq_spi.logic.options import SpiOptions, parse_channel_map
from tests.test_logic import _saleae2

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

MAP = "h2e=SPI [1]:mosi,e2h=SPI [2]"  # analyzers named so need the map: plot and monitor
# read no such capture before they took the pipeline's options


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """1.5 s of the emulator (boot, Running Vision at 0.53 s) as pcapng: big enough for the
    fast path (unless ``EYEQ_SPI_EXACT=1``)."""
    path = tmp_path_factory.mktemp("pipe") / "demo.pcapng"
    assert main(["demo", "--virtual-time", "--duration", "1.5", "--capture", str(path),
                 "--json"]) == 0
    assert path.stat().st_size >= pipeline.SMALL_INPUT
    return path


@pytest.fixture(scope="module")
def demo_records(demo: Path) -> list[Transfer]:
    with demo.open("rb") as fh:
        return list(read_pcapng(fh))


@pytest.fixture(scope="module")
def saleae(demo: Path, demo_records: list[Transfer]) -> Path:
    """The same transfers as a Saleae Logic 2 export of two analyzers not named after their
    direction, under the same file name (plots and screens name the file)."""
    d = demo.parent / "saleae"
    d.mkdir(exist_ok=True)
    path = d / demo.name
    path.write_text(_saleae2(demo_records, {"h2e": "SPI [1]", "e2h": "SPI [2]"}))
    return path


def _json(capsys: pytest.CaptureFixture[str], *argv: str) -> list[dict[str, Any]]:
    rc, out, err = _run(capsys, "dissect", *argv, "--json")
    assert rc == 0, err
    return [json.loads(line) for line in out.splitlines()]


# -- the library -------------------------------------------------------------------------------
@pytest.mark.parametrize("exact", ["1", "0"], ids=["reference", "fast"])
def test_dissect_files_hands_out_what_dissect_prints(demo: Path, exact: str,
                                                     capsys: pytest.CaptureFixture[str],
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(twins.EXACT_ENV, exact)
    want = _json(capsys, str(demo), str(demo))
    run = dissect_files([str(demo), str(demo)])
    got = json.loads(json.dumps(list(run)))  # tuples and floats as the JSON writer spells them
    assert got == want
    assert [cf.release.text for cf in run.files] == ["9.0", "9.0"] and run.ignored == 0
    jobs = list(dissect_files([str(demo), str(demo)], DissectConfig(jobs=2)))
    assert json.loads(json.dumps(jobs)) == want


def _recorder(seen: list[tuple[str | None, float, float | None]]) -> pipeline.Progress:
    def progress(path: str | None, done: float, total: float | None) -> None:
        seen.append((path, done, total))

    return progress


def test_dissect_files_reports_progress_and_a_cut_tail(demo: Path, tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    cut = tmp_path / "cut.pcapng"
    cut.write_bytes(demo.read_bytes()[:-8])
    for exact in ("1", "0"):  # the references, then the fast path
        monkeypatch.setenv(twins.EXACT_ENV, exact)
        seen: list[tuple[str | None, float, float | None]] = []
        run = dissect_files([str(cut)], progress=_recorder(seen))
        n = sum(1 for _ in run)
        size = cut.stat().st_size
        assert n and run.ignored > 0 and run.files[0].tail.ignored == run.ignored
        assert seen[-1] == (str(cut), size, size)
        assert [d for _, d, _ in seen] == sorted(d for _, d, _ in seen)


def test_the_logic_options_reach_the_reader(saleae: Path, demo: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    cfg = DissectConfig(spi=SpiOptions(channel_map=parse_channel_map(MAP)))
    got = [{k: v for k, v in r.items() if k != "file"} for r in dissect_files([str(saleae)], cfg)]
    want = [{k: v for k, v in r.items() if k != "file"} for r in _json(capsys, str(demo))]
    assert json.loads(json.dumps(got)) == want


# -- plot --------------------------------------------------------------------------------------
def test_plot_reads_a_saleae_export_like_the_capture(saleae: Path, demo: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib", reason="plot needs matplotlib (the [plot] extra)")
    from eyeq_spi.plot.collect import Collector, Window, collect

    def data(path: Path, spi: SpiOptions | None) -> Any:
        col = Collector(MessageCodec(None), Window(), timing=True, link=True)
        return collect(str(path), col, spi=spi)

    a = data(demo, None)
    b = data(saleae, SpiOptions(channel_map=parse_channel_map(MAP)))
    assert a.streams and dataclasses.asdict(a) == dataclasses.asdict(b)
    for kind in ("--timing", "--link"):
        pngs = []
        for path, extra in ((demo, []), (saleae, ["--channel-map", MAP])):
            out = path.parent / f"x{kind}.png"
            rc, _, err = _run(capsys, "plot", kind, str(path), *extra, "-o", str(out))
            assert rc == 0 and not err, err
            pngs.append(out.read_bytes())
        assert pngs[0] == pngs[1], kind


# -- monitor ---------------------------------------------------------------------------------
def test_monitor_replays_a_saleae_export_like_the_capture(saleae: Path, demo: Path,
                                                          capsys: pytest.CaptureFixture[str]
                                                          ) -> None:
    pytest.importorskip("rich", reason="monitor needs rich")
    from eyeq_spi.monitor.sources import DissectSource, ReplaySource
    from tests.test_monitor import _drain

    cfg = DissectConfig(spi=SpiOptions(channel_map=parse_channel_map(MAP)), pace_gc=False)
    for source in (lambda cf: ReplaySource(cf, speed=0),
                   lambda cf: DissectSource(cf, MessageCodec(None), speed=0)):
        snaps = [_drain(source(open_capture_file(str(p), cfg))) for p in (demo, saleae)]
        # rates and the scene's times depend on where the wall clock cut the redraws (as
        # fast as possible: one every 10 ms of wall time); counts, states and objects do not
        a, b = ((s.source, s.state, s.transitions, s.link, s.errors,
                 [(r.name, r.count) for r in s.rates], [o.id for o in s.scene.objects])
                for s in snaps)
        assert snaps[0].state == "RUNNING_VISION" and a == b
    for mode in ([], ["--passive"]):  # the command line takes the map (it did not before)
        shot = saleae.parent / "m.txt"
        rc, _, err = _run(capsys, "monitor", "--replay", str(saleae), "--channel-map", MAP,
                          *mode, "--pace", "0", "--screenshot", str(shot))
        assert rc == 0 and not err, err
        assert "RUNNING_VISION" in shot.read_text()


# -- export and replay -------------------------------------------------------------------------
def _mdf_content(path: Path) -> dict[str, Any]:
    asammdf = pytest.importorskip("asammdf", reason="--mdf needs asammdf (the [export] extra)")
    mdf = asammdf.MDF(str(path))
    try:
        out: dict[str, Any] = {}
        for gi, g in enumerate(mdf.groups):
            for ci, ch in enumerate(g.channels):
                sig = mdf.get(ch.name, group=gi, index=ci, raw=True)
                out[f"{g.channel_group.acq_name}/{ch.name}"] = (
                    sig.samples.tolist(), sig.timestamps.tolist())
        return out
    finally:
        mdf.close()


def test_export_mdf_from_the_pipeline_equals_the_transfer_pass(
        saleae: Path, demo: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--mdf alone takes the pipeline (the fast path for a big pcapng); with --mcap it rides
    on the pass over the transfers. The MDF holds the same either way, and the Saleae export's
    MDF is the capture's."""
    pytest.importorskip("mcap", reason="--mcap needs mcap (the [export] extra)")
    runs = {}
    for name, path, extra in (("alone", demo, []),
                              ("with-mcap", demo, ["--mcap", str(tmp_path / "x.mcap")]),
                              ("saleae", saleae, ["--channel-map", MAP])):
        out = tmp_path / f"{name}.mf4"
        rc, text, err = _run(capsys, "export", str(path), "--mdf", str(out), *extra, "--json")
        assert rc == 0, err
        summary = json.loads(text)
        runs[name] = (summary["transfers"], summary["mdf"]["messages"], _mdf_content(out))
    assert runs["alone"][0] > 0 and runs["alone"] == runs["with-mcap"] == runs["saleae"]


def test_replay_reads_a_saleae_export_like_the_capture(saleae: Path, demo: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    def summary(*argv: str) -> dict[str, Any]:
        rc, out, err = _run(capsys, "replay", *argv, "--into-host", "--json")
        assert rc in (0, 1), err
        s = json.loads(out)
        return {k: v for k, v in s.items() if k not in ("wall_s", "cpu_s", "timing")}

    assert summary(str(saleae), "--channel-map", MAP) == summary(str(demo))


def test_open_capture_file_reads_stdin_too(demo: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    raw = io.BytesIO(demo.read_bytes())
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(raw))
    cf = open_capture_file("-")
    try:
        assert cf.release.text == "9.0" and sum(1 for _ in cf.transfers) > 0
    finally:
        cf.close()
