"""``eyeq-spi plot``: render known synthetic captures and read the pictures' pixels."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("matplotlib", reason="the plot extra (matplotlib) is not installed")

from eyeq_spi.cli import main
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.errors import MissingExtra
from eyeq_spi.link.frame import FrameCodec
from eyeq_spi.plot.birdseye import (
    CIPV_EDGE,
    DPI,
    LINE_COLOURS,
    REAR_M,
    SIGN_COLOUR,
    class_colour,
    layout,
)
from eyeq_spi.plot.charts import GAP_COLOUR, timing_figure
from eyeq_spi.plot.collect import Collector, Window, collect
from eyeq_spi.plot.figures import save_figure
from eyeq_spi.plot.perceived import OBSTACLES, ROAD, SIGNS
from eyeq_spi.transport.segment import segment
from tests.test_plot_scene import (
    LINES,
    OBJECTS,
    SIGNS_AT,
    frames_of,
    scene_messages,
    synthetic_capture,
    write_capture,
)

RANGE, LATERAL = 60.0, 12.0


def _rgb(hex_colour: str) -> tuple[float, float, float]:
    h = hex_colour.lstrip("#")
    return (int(h[0:2], 16) / 255, int(h[2:4], 16) / 255, int(h[4:6], 16) / 255)


def _image(path: Path) -> Any:
    from matplotlib.image import imread

    return imread(str(path))


def _pixel(long: float, lat: float) -> tuple[int, int]:
    """(row, column) of a point in metres in the whole view, computed from the published fixed
    layout alone."""
    lay = layout(RANGE, LATERAL)
    assert lay.zoom is None
    w, h = lay.figsize[0] * DPI, lay.figsize[1] * DPI
    left, bottom, width, height = lay.main
    x = w * (left + width * (LATERAL - lat) / (2 * LATERAL))  # x axis: +LATERAL .. -LATERAL
    y = h * (bottom + height * (long + REAR_M) / (RANGE + REAR_M))
    return int(h - y), int(x)


def test_the_view_is_true_to_scale() -> None:
    """A metre across is as many pixels as a metre along, in the whole view and in the zoom,
    and the zoom appears where the whole view is narrow."""
    for rng, lat, near in ((60.0, 12.0, None), (170.0, 12.0, None), (40.0, 30.0, None),
                           (170.0, 12.0, 65.0)):
        (fw, fh), main, zoom, zoom_range = layout(rng, lat, near)
        w, h = fw * DPI, fh * DPI
        assert main[2] * w / (2 * lat) == pytest.approx(main[3] * h / (rng + REAR_M))
        if zoom is not None:
            assert zoom[2] * w / (2 * lat) == pytest.approx(zoom[3] * h / (zoom_range + REAR_M))
            assert zoom_range < rng and zoom[0] >= main[0] + main[2]
    assert layout(170.0, 12.0).zoom is not None
    assert layout(170.0, 12.0, 65.0).zoom_range == 65.0


def _close(px: Any, colour: tuple[float, float, float], tol: float = 0.03) -> bool:
    return all(abs(float(px[i]) - colour[i]) <= tol for i in range(3))


def _near(img: Any, row: int, col: int, colour: tuple[float, float, float], r: int = 2,
          tol: float = 0.06) -> bool:
    return any(_close(img[row + dr, col + dc], colour, tol)
               for dr in range(-r, r + 1) for dc in range(-r, r + 1))


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return synthetic_capture(tmp_path_factory.mktemp("plot") / "scene.pcapng", duration=1.0)


@pytest.fixture(scope="module")
def birdseye_png(capture: Path) -> Path:
    out = capture.with_name("be.png")
    assert main(["plot", str(capture), "--birdseye", "--at", "0.5", "--range", str(RANGE),
                 "--lateral", str(LATERAL), "-o", str(out)]) == 0
    return out


def test_boxes_land_where_their_positions_say(birdseye_png: Path) -> None:
    img = _image(birdseye_png)
    size = layout(RANGE, LATERAL).figsize
    assert img.shape[:2] == (round(size[1] * DPI), round(size[0] * DPI))
    for oid, cls, lo, la, w, ln, _cipv, _v in OBJECTS:
        colour = _rgb(class_colour(cls))
        # the box spans [long, long + length] ahead of the rear middle, [lat - w/2, lat + w/2]
        for fl in (0.25, 0.75):
            for fw in (-0.25, 0.25):
                row, col = _pixel(lo + fl * ln, la + fw * w)
                assert _close(img[row, col], colour), (oid, fl, fw, img[row, col][:3])
        for outside in ((lo + ln / 2, la + w / 2 + 0.8),  # left of the box
                        (lo - 1.5, la + w / 4)):          # behind it
            row, col = _pixel(*outside)
            assert not _close(img[row, col], colour), (oid, outside)


def test_cipv_is_outlined(birdseye_png: Path) -> None:
    """A dark ring CIPV_PAD_PX behind the CIPV's rear edge; the box inside keeps its class's
    colour (test_boxes_land_where_their_positions_say)."""
    from eyeq_spi.plot.birdseye import CIPV_PAD_PX

    img = _image(birdseye_png)
    dark = _rgb(CIPV_EDGE)
    for oid, _cls, lo, la, w, _ln, cipv, _v in OBJECTS:
        row, col = _pixel(lo, la + w / 4)  # on the rear edge
        assert _near(img, row + round(CIPV_PAD_PX), col, dark, r=1, tol=0.15) == (cipv == 2), oid


def test_lanes_pass_where_their_polynomials_say(birdseye_png: Path) -> None:
    img = _image(birdseye_png)
    colour = _rgb(LINE_COLOURS["marker"])
    for name, (a0, a1, a2, a3, start, end, _) in LINES.items():
        for i in range(15):
            x = start + 1 + (end - start - 2) * i / 14
            y = a0 + a1 * x + a2 * x * x + a3 * x ** 3
            row, col = _pixel(x, y)
            assert _near(img, row, col, colour), (name, x, y)
            # one metre inside the curve there is no line (a wrong sign or term would be)
            row, col = _pixel(x, y - 1.0)
            assert not _near(img, row, col, colour, r=1), (name, x)
        # nothing beyond endRange
        row, col = _pixel(end + 4.0, a0 + a1 * (end + 4) + a2 * (end + 4) ** 2)
        assert not _near(img, row, col, colour, r=1), name


def test_signs_are_placed_where_reported(birdseye_png: Path) -> None:
    img = _image(birdseye_png)
    red = _rgb(SIGN_COLOUR)
    for lo, la, _typ in SIGNS_AT:
        row, col = _pixel(lo, la)
        assert _near(img, row, col, red, r=6, tol=0.1), (lo, la)
        assert _close(img[row, col], (1.0, 1.0, 1.0), tol=0.05)  # the ring's white face


def test_velocity_arrows_point_where_the_objects_go(birdseye_png: Path) -> None:
    """The arrow runs from the box's middle 0.5 s of velocity ahead (ARROW_S): black pixels
    ahead of a moving box up to its tip, none past it, none ahead of a standing object."""
    from eyeq_spi.plot.birdseye import ARROW_S

    img = _image(birdseye_png)
    black = (0.0, 0.0, 0.0)
    for oid, _cls, lo, la, _w, ln, _cipv, v in OBJECTS:
        tip = lo + ln / 2 + v * ARROW_S
        if v:
            for long in (lo + ln + 1.0, tip - 1.0):
                row, col = _pixel(long, la)
                assert _near(img, row, col, black, r=1, tol=0.25), (oid, long)
        row, col = _pixel((tip if v else lo + ln) + 1.5, la)
        assert not _near(img, row, col, black, r=1, tol=0.25), oid


CAR_SPEED, CAR_START = 20.0, 10.0  # the moving capture's car: long = CAR_START + CAR_SPEED * t


@pytest.fixture(scope="module")
def moving(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The synthetic scene, but the CIPV car (ID 3) drives away at CAR_SPEED m/s."""
    from eyeq_spi.codec.e2e import E2EState
    from tests.test_plot_scene import _fill_scene

    codec = MessageCodec(None)
    e2e = E2EState()
    msgs = []
    for k in range(18):
        t = k / 18
        obs = _fill_scene(codec, t)[OBSTACLES]
        obs["visObjects"]["visObs"][0]["physicalState"]["longDistance"] = (
            CAR_START + CAR_SPEED * t)
        msgs.append((t, OBSTACLES, codec.encode_dasp(OBSTACLES, obs, k, e2e)))
    return write_capture(tmp_path_factory.mktemp("moving") / "moving.pcapng", frames_of(msgs))


def _car_at(img: Any, long: float) -> bool:
    _oid, cls, _lo, la, _w, ln, _cipv, _v = OBJECTS[0]
    row, col = _pixel(long + ln / 2, la)
    return _close(img[row, col][:3], _rgb(class_colour(cls)), tol=0.1)


def test_at_draws_the_scene_of_that_moment(moving: Path) -> None:
    for at, k in ((0.25, 4), (0.52, 9)):  # the last obstacle message at or before T
        out = moving.with_name(f"at{at}.png")
        assert main(["plot", str(moving), "--birdseye", "--at", str(at), "--range", str(RANGE),
                     "--lateral", str(LATERAL), "-o", str(out)]) == 0
        img = _image(out)
        assert _car_at(img, CAR_START + CAR_SPEED * k / 18), at
        other = 9 if k == 4 else 4
        assert not _car_at(img, CAR_START + CAR_SPEED * other / 18), at


def test_animation_frames_follow_the_capture(moving: Path) -> None:
    """Each GIF frame at T shows the scene of the messages before T."""
    import numpy as np
    from PIL import Image, ImageSequence

    gif = moving.with_name("moving.gif")
    assert main(["plot", str(moving), "--birdseye", "--animate", "--fps", "4", "--end", "0.9",
                 "--range", str(RANGE), "--lateral", str(LATERAL), "-o", str(gif)]) == 0
    with Image.open(gif) as im:
        frames = [np.asarray(f.convert("RGB"), dtype=float) / 255
                  for f in ImageSequence.Iterator(im)]
    assert len(frames) == 4
    for i, k in ((1, 4), (2, 8), (3, 13)):  # frame at i/4 s: last message before it
        assert _car_at(frames[i], CAR_START + CAR_SPEED * k / 18), i
        assert not _car_at(frames[i], CAR_START + CAR_SPEED * (k + 5) / 18), i


def test_svg_and_html_are_self_contained(capture: Path) -> None:
    svg, page = capture.with_name("be.svg"), capture.with_name("be.html")
    assert main(["plot", str(capture), "--birdseye", "-o", str(svg)]) == 0
    assert main(["plot", str(capture), "--link", "-o", str(page)]) == 0
    assert svg.read_text().lstrip().startswith("<?xml")
    text = page.read_text()
    assert text.startswith("<!DOCTYPE html>") and "<svg" in text
    _no_network(text)


def test_animation_html_player(capture: Path) -> None:
    page = capture.with_name("anim.html")  # the GIF: test_animation_frames_follow_the_capture
    assert main(["plot", str(capture), "--birdseye", "--animate", "--fps", "2",
                 "-o", str(page)]) == 0
    text = page.read_text()
    assert "<script" in text and "data:image/png;base64" in text
    _no_network(text)  # matplotlib's player loads its icon font from a CDN: not ours


def _no_network(text: str) -> None:
    """No address a browser would fetch: only the SVG namespace names (identifiers, never
    loaded) may be written as http URLs."""
    addresses = set(re.findall(r"(?:https?:)?//[\w.-]+\.[a-z]{2,}[^\s\"'<>)]*", text))
    assert addresses <= {"http://www.w3.org/2000/svg", "http://www.w3.org/1999/xlink"}, addresses
    assert "<link" not in text and "@import" not in text


@pytest.fixture(scope="module")
def stopped(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # road data silent in [0.5, 0.9) s, obstacles stopped from 1.2 s to the end
    return synthetic_capture(tmp_path_factory.mktemp("timing") / "stopped.pcapng", duration=2.0,
                             stop={ROAD: (0.5, 0.9), OBSTACLES: (1.2, 99.0)})


def test_timing_marks_the_known_gaps(stopped: Path) -> None:
    col = collect(str(stopped), Collector(MessageCodec(None), Window(), timing=True))
    period = 1 / 18
    road, obs, signs = col.streams[ROAD], col.streams[OBSTACLES], col.streams[SIGNS]
    (a, b), = road.gaps(col.end)
    assert a == pytest.approx(math.ceil(0.5 * 18 - 1) * period, abs=0.01)  # last before 0.5
    assert b == pytest.approx(math.ceil(0.9 * 18) * period, abs=0.01)      # first after 0.9
    (a, b), = obs.gaps(col.end)
    assert a == pytest.approx(math.ceil(1.2 * 18 - 1) * period, abs=0.01) and b == col.end
    assert signs.gaps(col.end) == []
    assert road.counter_jumps == [pytest.approx(b_ := road.gaps(col.end)[0][1])] and b_
    assert obs.counter_jumps == [] and signs.counter_jumps == []

    fig, axes = timing_figure(col)
    png = stopped.with_name("timing.png")
    save_figure(fig, str(png), "timing")
    img = _image(png)
    height = img.shape[0]

    def tinted(name: str, t: float) -> bool:
        ax = axes[name]
        top = ax.get_ylim()[1]
        x, y = ax.transData.transform((t, top * 0.4))
        px = img[int(height - y), int(x)]
        return float(px[0]) > float(px[1]) + 0.15  # the red span over white

    assert _rgb(GAP_COLOUR)[0] > 0.8
    assert tinted(ROAD, 0.7) and not tinted(ROAD, 0.3) and not tinted(ROAD, 1.5)
    assert tinted(OBSTACLES, 1.6) and not tinted(OBSTACLES, 0.7)
    assert not tinted(SIGNS, 0.7) and not tinted(SIGNS, 1.6)


def test_link_counts_naks_crc_errors(tmp_path: Path) -> None:
    fc = FrameCodec()
    msgs = scene_messages(MessageCodec(None), duration=0.3)
    frames = frames_of(msgs)
    t, _, data = frames[10]
    bad = bytearray(data)
    bad[40] ^= 0xFF
    frames[10] = (t, "e2h", bytes(bad))  # a CRC error
    frames.insert(12, (t + 1e-5, "h2e", fc.nak(99, 1)))  # NAK reason 0x001
    # the obstacles transfer at 0.22 s (23 frames) loses its last frame and its ACK: the next
    # first frame aborts it (events carry no time: counted at their frame's)
    n = len(segment(msgs[0][2], 0))
    first = next(i for i, (tt, d, _x) in enumerate(frames) if d == "e2h" and tt >= 0.2)
    del frames[first + 2 * (n - 1):first + 2 * n]
    lost_at = frames[first + 2 * (n - 1)][0]  # the next transfer's first frame
    cap = write_capture(tmp_path / "link.pcapng", frames)
    col = collect(str(cap), Collector(MessageCodec(None), Window(), link=True))
    total: dict[str, int] = {}
    for c in col.link.values():
        for k, v in c.items():
            total[k] = total.get(k, 0) + v
    assert total["CRC errors"] == 1 and total["NAK 0x001"] == 1
    assert total["e2h DATA"] == sum(1 for _, d, _x in frames if d == "e2h")
    assert total["abort: num_gap"] == 1  # the transfer holding the CRC error, at 0 s
    assert total["abort: new_first_frame"] == 1
    (abort_bin,) = [b for b, c in col.link.items() if c["abort: new_first_frame"]]
    assert abort_bin == int(lost_at // col.link_bin) == 2
    out = tmp_path / "link.png"
    assert main(["plot", str(cap), "--link", "--bin", "50", "-o", str(out)]) == 0
    assert out.stat().st_size > 10_000


@pytest.mark.parametrize("argv, words", [
    (["--birdseye", "-o", "x.jpg"], "output must end in"),
    (["--timing", "--at", "1"], "--at and --animate go with --birdseye"),
    (["--birdseye", "--at", "999"], "--at 999: after the last record read, at 0.9"),
    (["--birdseye", "--animate", "-o", "x.png"], "output must end in"),
    (["--birdseye", "--fps", "-1"], "argument --fps: must be a number in (0, "),
])
def test_bad_arguments_exit_2(capture: Path, argv: list[str], words: str,
                              capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plot", str(capture), *argv]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1


def test_bad_inputs_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plot", str(tmp_path / "missing.pcapng"), "--timing"]) == 2
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x01\x02" * 300)
    assert main(["plot", str(junk), "--birdseye"]) == 2
    raw = tmp_path / "frames.raw"
    raw.write_bytes(b"".join(d for _, dd, d in frames_of(
        scene_messages(MessageCodec(None), 0.1)) if dd == "e2h"))
    assert main(["plot", str(raw), "--timing"]) == 2  # raw files carry no timestamps
    assert "no timestamps" in capsys.readouterr().err
    assert main(["plot", str(raw), "--birdseye", "-o", str(tmp_path / "raw.png")]) == 0


def test_missing_matplotlib_is_a_typed_error(monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    from eyeq_spi.plot.figures import mpl

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(MissingExtra, match=r"pip install 'eyeq-spi\[plot\]'"):
        mpl()


def test_help_lists_every_capture_format_read(capsys: pytest.CaptureFixture[str]) -> None:
    """The formats come from the io registry: a reader added there is named here too."""
    from eyeq_spi import io as formats

    with pytest.raises(SystemExit):
        main(["plot", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    positional = text.split("positional arguments:")[1].split("options:")[0]
    for name in formats.readers():
        assert re.search(rf"\b{name}\b", positional), (name, positional)
