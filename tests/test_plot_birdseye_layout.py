"""The bird's-eye figure's geometry (not its pixels): the zoom never cuts what it draws, the
CIPV keeps its class's colour, labels overlap nothing, the figure is fitted to its content."""

from __future__ import annotations

import itertools
from typing import Any

import pytest

pytest.importorskip("matplotlib", reason="the plot extra (matplotlib) is not installed")

from eyeq_spi.plot.birdseye import ARROW_S, birdseye, class_colour
from eyeq_spi.plot.perceived import Scene, SceneLine, SceneObject, SceneSign


def _obj(oid: int, cls: int, long: float, lat: float, v: float = 0.0, cipv: bool = False,
         length: float = 4.5, width: float = 1.8) -> SceneObject:
    return SceneObject(id=oid, cls=cls, cls_name=f"class{cls}", long=long, lat=lat, width=width,
                       length=length, heading=0.0, v_long=v, v_lat=0.0, cipv=cipv, ttc=None)


def _line(name: str, kind: str, a0: float, end: float, type_name: str = "SOLID") -> SceneLine:
    return SceneLine(name, kind, (a0, 0.0, 0.0, 0.0), 5.0, end, type_name)


# a scene like the demo's: the CIPV just beyond the zoom's usual 42 m, two signs at 42 m, lanes
# beside the objects and far objects that make the whole view a narrow strip
SCENE = Scene(time=4.0, objects=[
    _obj(3, 0, 41.0, 0.0, v=4.0, cipv=True), _obj(1, 0, 15.5, -3.5, v=20.0),
    _obj(7, 0, 18.7, 3.5, v=25.0), _obj(9, 4, 66.0, -3.0, v=12.0),
    _obj(4, 1, 104.0, 3.5, v=28.0, length=13.0, width=2.5), _obj(8, 0, 143.0, 3.7, v=20.0),
    _obj(2, 0, -9.5, -3.4, v=16.0)],
    lines=[_line("hostLeftMarker", "marker", 1.8, 52.0, "DASHED"),
           _line("hostRightMarker", "marker", -1.8, 52.0, "DASHED"),
           _line("leftMarker", "marker", 5.4, 50.0), _line("rightMarker", "marker", -5.4, 50.0),
           _line("leftRoadBorder", "border", 6.3, 45.0),
           _line("rightRoadBorder", "border", -6.3, 45.0),
           _line("laneCenter", "centre", 0.0, 60.0)],
    signs=[SceneSign(42.0, 7.5, 2.0, 1, "Speed Limit 80"),
           SceneSign(42.0, -7.5, 2.0, 1, "Speed Limit 80"),
           SceneSign(93.0, -7.5, 2.0, 2, "Motorway Begin")])


@pytest.fixture(scope="module")
def fig() -> Any:
    figure = birdseye(SCENE)
    figure.canvas.draw()
    assert len(figure.axes) == 2  # the whole view and the zoom
    return figure


def test_the_zoom_cuts_no_object_and_no_sign(fig: Any) -> None:
    top = fig.axes[1].get_ylim()[1]
    for o in SCENE.objects:
        near, far = o.long, max(o.long + o.length, o.long + o.length / 2 + o.v_long * ARROW_S)
        assert far < top or near > top, (o.id, near, far, top)
    for s in SCENE.signs:
        assert s.long + 1.0 < top or s.long - 1.0 > top, (s.long, top)


def _box_patches(ax: Any, o: SceneObject) -> list[Any]:
    """The filled patches whose corners are the object's box."""
    from matplotlib.patches import Polygon

    want = sorted((round(x, 6), round(y, 6)) for x, y in (
        (o.lat - o.width / 2, o.long), (o.lat + o.width / 2, o.long),
        (o.lat - o.width / 2, o.long + o.length), (o.lat + o.width / 2, o.long + o.length)))
    found = []
    for p in ax.patches:
        if isinstance(p, Polygon) and p.get_fill():
            got = sorted({(round(x, 6), round(y, 6)) for x, y in p.get_xy()})
            if got == want:
                found.append(p)
    return found


def test_the_cipv_keeps_its_class_colour(fig: Any) -> None:
    """In both panels its box is filled with its class's colour, and the outline drawn on the
    box leaves most of it visible (a thick outline on a small box reads as a black box)."""
    from matplotlib.colors import to_rgb

    cipv = next(o for o in SCENE.objects if o.cipv)
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        (box,) = _box_patches(ax, cipv)
        assert to_rgb(box.get_facecolor()) == pytest.approx(to_rgb(class_colour(cipv.cls)))
        width_px = box.get_window_extent(renderer).width
        edge_px = box.get_linewidth() * fig.dpi / 72
        assert (width_px - edge_px) / width_px >= 0.6, (ax.get_title(), width_px, edge_px)


def _labels(ax: Any) -> list[Any]:
    return [t for t in ax.texts if t.get_text() and t.get_visible()]


def test_labels_overlap_no_label_arrow_or_lane(fig: Any) -> None:
    from matplotlib.patches import FancyArrowPatch

    renderer = fig.canvas.get_renderer()
    named = 0
    for ax in fig.axes:
        boxes = [t.get_window_extent(renderer) for t in _labels(ax)]
        named += len(boxes)
        for a, b in itertools.combinations(boxes, 2):
            assert not a.overlaps(b), (a, b)
        arrows = [p.get_window_extent(renderer) for p in ax.patches
                  if isinstance(p, FancyArrowPatch)]
        lanes = [ln.get_transform().transform(ln.get_xydata()) for ln in ax.get_lines()
                 if len(ln.get_xydata()) > 1]
        for box in boxes:
            for arrow in arrows:
                assert not box.overlaps(arrow), (box, arrow)
            for points in lanes:
                assert not any(box.contains(x, y) for x, y in points), box
    assert named >= len(SCENE.objects) + 2  # every object (zoom or whole view) and the signs


def test_the_figure_is_fitted_to_its_content(fig: Any) -> None:
    """No wide empty band: the panels and the legend stand side by side with small gaps, the
    legend ends near the right edge."""
    renderer = fig.canvas.get_renderer()
    parts = sorted([ax.get_tightbbox(renderer) for ax in fig.axes]
                   + [lg.get_window_extent(renderer) for lg in fig.legends], key=lambda b: b.x0)
    inch = fig.dpi
    for left, right in itertools.pairwise(parts):
        assert right.x0 - left.x1 <= 0.6 * inch, (left, right)
    assert fig.bbox.x1 - parts[-1].x1 <= 0.5 * inch
    assert parts[0].x0 <= 0.5 * inch
    for part in parts:
        assert part.x1 <= fig.bbox.x1  # nothing cut at the right edge


def test_a_thing_outside_a_panel_is_not_named_in_it() -> None:
    """A zoom fixed for a whole animation can end just before an object of one frame: the
    zoom names only what it shows."""
    from eyeq_spi.plot.birdseye import draw_scene, new_axes

    _figure, axes = new_axes(160.0, 12.0, 40.0)
    draw_scene(axes, SCENE, 160.0, 12.0)  # the CIPV's middle is at 43 m, beyond the zoom
    assert axes[1].get_ylim()[1] == 40.0
    names = {t.get_text() for t in _labels(axes[1])}
    assert "3 CIPV" not in names and "3 CIPV" in {t.get_text() for t in _labels(axes[0])}


def test_a_sign_the_eyeq_cannot_place_is_listed_not_drawn() -> None:
    """A sign whose distance the EyeQ does not know (§12.2: its position at the field's limit)
    has no place on the road: it is not drawn, does not stretch the view to 127 m, and the
    legend names it as unplaced."""
    scene = Scene(time=1.0, objects=[_obj(3, 0, 30.0, 0.0)],
                  signs=[SceneSign(127.5, 0.0, 0.0, 1, "Speed Limit 80", known=False)])
    figure = birdseye(scene)
    figure.canvas.draw()
    assert figure.axes[0].get_ylim()[1] < 100  # fitted to the object at 30 m
    assert not [ln for ax in figure.axes for ln in ax.lines if ln.get_marker() == "o"]
    texts = [t.get_text() for legend in figure.legends for t in legend.get_texts()]
    assert any("Speed Limit 80, position unknown" in t for t in texts), texts
