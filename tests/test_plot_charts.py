"""What a reviewer checks in a plot: every mark explained, lines that do not hide one another,
titles that read right, the time axis of ``dissect``."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytest.importorskip("matplotlib", reason="the plot extra (matplotlib) is not installed")

from eyeq_spi.cli import main
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.plot.birdseye import birdseye
from eyeq_spi.plot.charts import TIME_LABEL, link_figure, timing_figure
from eyeq_spi.plot.collect import Collector, Window, collect
from eyeq_spi.plot.perceived import OBSTACLES, ROAD, Scene, SceneSign
from tests.test_plot_scene import synthetic_capture


@pytest.fixture(scope="module")
def stopped(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return synthetic_capture(tmp_path_factory.mktemp("review") / "stopped.pcapng", duration=2.0,
                             stop={ROAD: (0.5, 0.9), OBSTACLES: (1.2, 99.0)})


def _legend_labels(fig: object) -> list[str]:
    labels = [t.get_text() for lg in fig.legends for t in lg.get_texts()]  # type: ignore[attr-defined]
    for ax in fig.axes:  # type: ignore[attr-defined]
        lg = ax.get_legend()
        if lg is not None:
            labels += [t.get_text() for t in lg.get_texts()]
    return labels


def test_every_timing_mark_is_in_the_legend(stopped: Path) -> None:
    col = collect(str(stopped), Collector(MessageCodec(None), Window(), timing=True))
    fig, axes = timing_figure(col)
    labels = " | ".join(_legend_labels(fig))
    markers = {line.get_marker() for ax in axes.values() for line in ax.get_lines()}
    assert {"^", "x", "."} <= markers  # gaps above the axis, counter jumps, arrivals drawn
    for words in ("gap above the axis", "counter jump", "inter-arrival", "nominal period",
                  "tolerance", "stopped"):
        assert words in labels, (words, labels)
    assert next(iter(axes.values())).figure.axes[-1].get_xlabel() == TIME_LABEL


def _extents(fig: object) -> tuple[object, list[object], list[object]]:
    """The title's, the legends' and the axes' (with their texts) boxes in pixels."""
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    title = fig._suptitle.get_window_extent(renderer)  # type: ignore[attr-defined]
    legends = [lg.get_window_extent(renderer) for lg in fig.legends]  # type: ignore[attr-defined]
    axes = [ax.get_tightbbox(renderer) for ax in fig.axes]  # type: ignore[attr-defined]
    return title, legends, axes


def test_timing_title_legend_and_rows_do_not_overlap(stopped: Path) -> None:
    """With few rows and with as many as a whole EyeQ sends (the figure grows with them)."""
    import dataclasses

    col = collect(str(stopped), Collector(MessageCodec(None), Window(), timing=True))
    many = dataclasses.replace(col, streams=dict(col.streams))
    first = next(s for s in col.streams.values() if s.period is not None)
    for k in range(14):
        many.streams[f"COPY_{k}"] = dataclasses.replace(first, name=f"COPY_{k}")
    for data in (col, many):
        _timing_layout_holds(timing_figure(data)[0])


def _timing_layout_holds(fig: object) -> None:
    title, legends, axes = _extents(fig)
    for box in legends + axes:
        assert not title.overlaps(box), (title, box)  # type: ignore[attr-defined]
    for lg in legends:
        for box in axes:
            assert not lg.overlaps(box), (lg, box)  # type: ignore[attr-defined]
        assert lg.y1 <= fig.bbox.y1  # type: ignore[attr-defined]


def test_link_lines_do_not_hide_one_another(stopped: Path) -> None:
    col = collect(str(stopped), Collector(MessageCodec(None), Window(), link=True,
                                          link_bin=0.1))
    fig = link_figure(col)
    for ax in fig.axes:
        lines = [ln for ln in ax.get_lines() if ln.get_label() and
                 not ln.get_label().startswith("_")]
        looks = [(ln.get_color(), ln.get_linestyle(), ln.get_linewidth()) for ln in lines]
        assert len(set(looks)) == len(looks)
        widths = [w for _, _, w in looks]
        assert widths == sorted(widths, reverse=True)  # widest first: equal series nest
    directions = [ax.get_ylabel() for ax in fig.axes[:2]]
    assert "EyeQ" in directions[0] and "host" in directions[1]
    assert all(ln.get_label().startswith("e2h") for ln in fig.axes[0].get_lines())
    assert re.search(r"link: \d+ frames, 0 NAKs, 0 errors", fig._suptitle.get_text())


def test_each_timing_row_states_its_rate_while_it_runs(stopped: Path) -> None:
    """The row's rate is stream_rate's (as dissect --stats and monitor): ROAD's 0.4 s silence
    is a gap left out, not averaged in (which would read about 14.5 Hz)."""
    col = collect(str(stopped), Collector(MessageCodec(None), Window(), timing=True))
    _fig, axes = timing_figure(col)
    texts = {name: " ".join(t.get_text() for t in ax.texts) for name, ax in axes.items()}
    assert "rate 18.0 Hz (1 gap left out)," in texts[ROAD], texts[ROAD]
    assert re.match(r"rate 18\.0 Hz, \d+ messages", texts[OBSTACLES]), texts[OBSTACLES]


def test_titles_count_in_words() -> None:
    scene = Scene(time=1.0, signs=[SceneSign(long=30.0, lat=-5.0, height=1.0, type=1,
                                             name="Speed Limit 50")])
    fig = birdseye(scene, 60.0, 12.0)
    title = fig._suptitle.get_text()
    assert "0 objects, 0 lines, 1 sign;" in title and "1 signs" not in title


def test_plot_time_is_dissect_time(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The same origin: the capture's first transfer. The demo's first transfer is at 0.15 s of
    its own clock; both views put it at 0."""
    cap = tmp_path / "d.pcapng"
    main(["demo", "--virtual-time", "--duration", "1.2", "--capture", str(cap), "--json"])
    capsys.readouterr()
    assert main(["dissect", str(cap), "--id", "0xE4", "--no-tree"]) == 0
    first_line = capsys.readouterr().out.splitlines()[0]
    dissect_t = float(first_line.split()[0])
    col = collect(str(cap), Collector(MessageCodec(None), Window(), timing=True))
    assert col.streams[OBSTACLES].times[0] == pytest.approx(dissect_t, abs=2e-6)
