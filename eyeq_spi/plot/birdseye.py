"""The ego vehicle's view from above (``eyeq-spi plot --birdseye``).

Lateral goes left-to-right as the driver sees it (``lat`` left positive: the x axis is
inverted), longitudinal goes up, both at the same scale; where the whole view is narrow a second
panel zooms on the near range. The layout is computed (:func:`layout`) so that a pixel of the PNG
maps back to metres; the tests rely on that.

- an object is a box ``width`` by ``length`` whose rear middle is at (``longDistance``,
  ``latDistance``) (§13.2.5.3), turned by ``heading``, in its class's colour, labelled with its
  ID clear of every other mark; the CIPV gets a black ring a few pixels outside its box;
- the velocity arrow shows where the absolute velocity carries the object in ARROW_S seconds;
- lines are drawn from their polynomials over ``[startRange, endRange]``; a sign is a ring.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from eyeq_spi.plot.figures import new_figure, plural
from eyeq_spi.plot.labels import Label, place_labels
from eyeq_spi.plot.perceived import Scene, SceneLine, SceneObject, SceneSign
from eyeq_spi.plot.vehicle_frame import box_centre

DPI = 100
PANEL_IN = 7.7  # the panels' height, inches
BOTTOM_IN, TOP_IN = 0.55, 0.75  # below the panels (axis labels), above them (titles)
LEFT_IN = 0.75  # left of the whole view (its axis labels)
GAP_IN = 0.75  # between the panels (room for the zoom's axis labels)
LEGEND_IN = 2.8  # right of the last panel, for the legend
MAIN_MAX_IN = 7.0  # the whole view's widest
ZOOM_MAX_IN = 3.6  # the zoom's widest
MIN_HEIGHT_IN = 6.5  # the legend's room when the view is wide and flat
MAX_SIGN_NAMES = 8  # signs named in the legend (the whole view is too narrow for labels)
REAR_M = 10.0  # metres shown behind the ego vehicle's origin
NEAR_MARGIN_M = 2.0  # the zoom ends at least this far from anything drawn
ARROW_S = 0.5  # velocity arrows show 0.5 s of travel
EGO = (4.5, 1.8)  # length, width of the ego vehicle drawn behind the origin (not in the data)
CIPV_PAD_PX = 4.0  # the CIPV's ring stands this far outside its box
BACKGROUND = "#f2f2f2"
CIPV_EDGE = "#000000"
CIPV_WIDTH = 2.0  # points
LINE_COLOURS = {"marker": "#50509a", "border": "#a0522d", "centre": "#2ca02c"}
SIGN_COLOUR = "#d00000"
_TAB10 = ("#1f77b4", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
          "#17becf")


def class_colour(cls: int) -> str:
    """object_classification value -> fill colour (car blue, truck orange, ...)."""
    return _TAB10[cls % len(_TAB10)]


def placed(scene: Scene) -> list[SceneSign]:
    """The signs whose position the EyeQ knows (§12.2): the others have no place to draw."""
    return [sign for sign in scene.signs if sign.known]


def view_limits(scenes: Sequence[Scene], range_m: float | None = None,
                lateral_m: float | None = None) -> tuple[float, float]:
    """(forward range, lateral half-width) in metres: given, or fitted to what is drawn."""
    if range_m is None:
        far = 40.0
        for sc in scenes:
            far = max(far, *(o.long + o.length for o in sc.objects), *(ln.end for ln in sc.lines),
                      *(s.long for s in placed(sc)), 0.0)
        range_m = min(250.0, math.ceil((far + 5.0) / 10.0) * 10.0)
    if lateral_m is None:
        wide = 10.0
        for sc in scenes:
            wide = max(wide, *(abs(o.lat) + o.width for o in sc.objects),
                       *(abs(s.lat) + 1.0 for s in placed(sc)), 0.0)
            for ln in sc.lines:
                wide = max(wide, abs(ln.lateral(ln.start)), abs(ln.lateral(ln.end)))
        lateral_m = min(100.0, math.ceil(wide + 2.0))
    return range_m, lateral_m


def box_corners(obj: SceneObject, pad: float = 0.0) -> list[tuple[float, float]]:
    """The box's corners as (lat, long), starting at the rear right, counter-clockwise;
    ``pad`` metres wider on every side."""
    ch, sh = math.cos(obj.heading), math.sin(obj.heading)
    fwd = (ch, sh)  # (long, lat) of the object's forward axis
    left = (-sh, ch)
    hw = obj.width / 2.0 + pad
    pts = []
    for along, side in ((-pad, -hw), (obj.length + pad, -hw), (obj.length + pad, hw), (-pad, hw)):
        lo = obj.long + along * fwd[0] + side * left[0]
        la = obj.lat + along * fwd[1] + side * left[1]
        pts.append((la, lo))
    return pts


def _middle(obj: SceneObject) -> tuple[float, float]:
    """(lat, long) of the box's middle."""
    x, y = box_centre(obj.long, obj.lat, obj.length, obj.heading)
    return y, x


def _arrow_tip(obj: SceneObject) -> tuple[float, float]:
    cx, cy = _middle(obj)
    return cx + obj.v_lat * ARROW_S, cy + obj.v_long * ARROW_S


def _extent(obj: SceneObject) -> tuple[float, float]:
    """The longitudinal span an object's drawing covers: its box and its velocity arrow."""
    longs = [lo for _, lo in box_corners(obj)] + [_arrow_tip(obj)[1]]
    return min(longs), max(longs)


def line_points(ln: SceneLine, step: float = 0.5) -> tuple[list[float], list[float]]:
    points = max(2, int((ln.end - ln.start) / step) + 1)
    xs = [ln.start + (ln.end - ln.start) * i / (points - 1) for i in range(points)]
    return [ln.lateral(x) for x in xs], xs


Rect = tuple[float, float, float, float]  # left, bottom, width, height (figure fractions)


class Layout(NamedTuple):
    """Where the panels stand: the figure's size in inches, the whole view's rectangle, the
    zoom's (None when the whole view is wide enough to read) and the zoom's forward range."""

    figsize: tuple[float, float]
    main: Rect
    zoom: Rect | None
    zoom_range: float


def near_base(lateral_m: float) -> float:
    """The zoom's forward range when it is as wide as it may be and as tall as the panels."""
    zoom_ppm = min(ZOOM_MAX_IN * DPI / (2 * lateral_m), PANEL_IN * DPI / (REAR_M + 10.0))
    return PANEL_IN * DPI / zoom_ppm - REAR_M


def near_range(scenes: Sequence[Scene], lateral_m: float) -> float:
    """The zoom's forward range: :func:`near_base`, pushed past every object (box and arrow)
    and sign it would cut, with NEAR_MARGIN_M to spare."""
    spans = [_extent(o) for sc in scenes for o in sc.objects]
    spans += [(s.long - 1.0, s.long + 1.0) for sc in scenes for s in placed(sc)]
    cut = near_base(lateral_m)
    moved = True
    while moved:
        moved = False
        for lo, hi in spans:
            if lo - NEAR_MARGIN_M < cut < hi + NEAR_MARGIN_M:
                cut, moved = hi + NEAR_MARGIN_M, True
    return float(math.ceil(cut))


def layout(range_m: float, lateral_m: float, near_m: float | None = None) -> Layout:
    """The figure fitted to its panels and the legend: both panels have equal scales (the
    rectangles' pixel sizes are in the ratio of the metres they show); the zoom shows
    ``near_m`` metres ahead (default :func:`near_base`) and is left out when it would not be
    at least 1.5 times larger than the whole view or reach as far."""
    span = range_m + REAR_M
    ppm = min(PANEL_IN * DPI / span, MAIN_MAX_IN * DPI / (2 * lateral_m))  # pixels per metre
    main_w, main_h = 2 * lateral_m * ppm, span * ppm
    near = near_base(lateral_m) if near_m is None else near_m
    zoom_ppm = min(PANEL_IN * DPI / (near + REAR_M), ZOOM_MAX_IN * DPI / (2 * lateral_m))
    with_zoom = zoom_ppm >= 1.5 * ppm and near < range_m
    zoom_w = 2 * lateral_m * zoom_ppm if with_zoom else 0.0
    zoom_h = (near + REAR_M) * zoom_ppm if with_zoom else 0.0
    panels_h = max(main_h, zoom_h)
    height = max(MIN_HEIGHT_IN * DPI, BOTTOM_IN * DPI + panels_h + TOP_IN * DPI)
    width = (LEFT_IN * DPI + main_w + (GAP_IN * DPI + zoom_w if with_zoom else 0.0)
             + LEGEND_IN * DPI)
    top = (height - TOP_IN * DPI) / height  # panels hang from here
    main: Rect = (LEFT_IN * DPI / width, top - main_h / height, main_w / width, main_h / height)
    if not with_zoom:
        return Layout((width / DPI, height / DPI), main, None, range_m)
    zoom: Rect = ((LEFT_IN * DPI + main_w + GAP_IN * DPI) / width, top - zoom_h / height,
                  zoom_w / width, zoom_h / height)
    return Layout((width / DPI, height / DPI), main, zoom, near)


def new_axes(range_m: float, lateral_m: float, near_m: float | None = None
             ) -> tuple[Any, list[Any]]:
    """The figure and its panels: the whole view, and the zoom when :func:`layout` has one."""
    lay = layout(range_m, lateral_m, near_m)
    fig = new_figure(*lay.figsize, DPI)
    axes = [fig.add_axes(lay.main)]
    if lay.zoom is not None:
        axes.append(fig.add_axes(lay.zoom))
    for index, ax in enumerate(axes):
        _frame(ax, range_m if index == 0 else lay.zoom_range, lateral_m)
    return fig, axes


def _frame(ax: Any, range_m: float, lateral_m: float) -> None:
    ax.set_facecolor(BACKGROUND)
    ax.set_xlim(lateral_m, -lateral_m)  # left of the car on the left
    ax.set_ylim(-REAR_M, range_m)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("lateral (m, left +)")
    ax.set_ylabel("longitudinal (m)")
    ax.grid(True, color="#dddddd", linewidth=0.5, zorder=0)


def draw_scene(axes: Any, scene: Scene, range_m: float, lateral_m: float,
               title: str | None = None) -> None:
    """Draw ``scene`` into each panel of ``axes`` (one axes or the list from
    :func:`new_axes`); the legend and title go with the figure."""
    axes = axes if isinstance(axes, list) else [axes]
    zoom_range = axes[1].get_ylim()[1] if len(axes) > 1 else range_m
    for index, ax in enumerate(axes):
        ax.clear()
        _frame(ax, range_m if index == 0 else zoom_range, lateral_m)
        # the whole view beside a zoom names only what the zoom does not show
        named = (lambda lo: True) if index or len(axes) == 1 else (lambda lo: lo > zoom_range)
        _draw_panel(ax, scene, lateral_m, named, signs_named=bool(index or len(axes) == 1))
    if len(axes) > 1:  # where the zoom is, on the whole view
        from matplotlib.patches import Rectangle

        axes[0].add_patch(Rectangle((-lateral_m, -REAR_M), 2 * lateral_m, zoom_range + REAR_M,
                                    fill=False, edgecolor="#404040", linestyle="--",
                                    linewidth=1.0, zorder=7))
        axes[1].set_title(f"near range, {zoom_range:.0f} m (zoom)", fontsize=9)
        axes[0].set_title("whole view", fontsize=9)
    fig = axes[0].figure
    for old in list(fig.legends):
        old.remove()
    right = axes[-1].get_position().x1 + 0.12 / fig.get_figwidth()
    fig.legend(handles=_legend(scene, len(axes) > 1), loc="upper left",
               bbox_to_anchor=(right, axes[0].get_position().y1), fontsize=8)
    when = "end of capture" if scene.time is None else f"t = {scene.time:.2f} s"
    fig.suptitle(title or f"{when} (s since the capture's first transfer): "
                 f"{plural(len(scene.objects), 'object')}, {plural(len(scene.lines), 'line')}, "
                 f"{plural(len(scene.signs), 'sign')}; equal scales", fontsize=10)


def _draw_panel(ax: Any, scene: Scene, lateral_m: float, named: Callable[[float], bool],
                signs_named: bool) -> None:
    """One panel's marks, then its labels placed clear of them."""
    from matplotlib.patches import FancyArrowPatch, Polygon, Rectangle

    ppm = ax.get_window_extent().width / (2 * lateral_m)  # pixels per metre
    length, width = EGO
    marks = [ax.add_patch(Rectangle((-width / 2, -length), width, length, facecolor="#ffffff",
                                    edgecolor="#000000", hatch="//", linewidth=1.0, zorder=2))]
    lanes = []
    for ln in scene.lines:
        lat, lon = line_points(ln)
        style = "--" if ln.type_name == "DASHED" else (":" if ln.kind == "centre" else "-")
        lanes += ax.plot(lat, lon, style, color=LINE_COLOURS[ln.kind],
                         linewidth=2.5 if ln.kind == "border" else 2.0, zorder=3)
    labels = []
    for obj in scene.objects:
        if obj.v_long or obj.v_lat:  # drawn under the box: only the part outside it shows
            marks.append(ax.add_patch(FancyArrowPatch(
                _middle(obj), _arrow_tip(obj), zorder=4, arrowstyle="-|>", mutation_scale=10,
                color="#000000", linewidth=1.2)))
        marks.append(ax.add_patch(Polygon(box_corners(obj), closed=True, zorder=5,
                                          facecolor=class_colour(obj.cls), edgecolor="#202020",
                                          linewidth=0.6)))
        if obj.cipv:  # a ring around the box: the box keeps its class's colour
            marks.append(ax.add_patch(Polygon(
                box_corners(obj, CIPV_PAD_PX / ppm), closed=True, fill=False, zorder=5,
                edgecolor=CIPV_EDGE, linewidth=CIPV_WIDTH, gid="cipv")))
        if named(obj.long):
            half = (obj.width / 2 * ppm + (CIPV_PAD_PX + 2 if obj.cipv else 0),
                    obj.length / 2 * ppm + (CIPV_PAD_PX + 2 if obj.cipv else 0))
            labels.append(Label(f"{obj.id}" + (" CIPV" if obj.cipv else ""), _middle(obj), half))
    for sign in placed(scene):
        marks += ax.plot([sign.lat], [sign.long], "o", markersize=9, markerfacecolor="#ffffff",
                         markeredgecolor=SIGN_COLOUR, markeredgewidth=2.0, zorder=5)
        if signs_named:  # the narrow whole view has no room: the legend names them
            labels.append(Label(sign.name, (sign.lat, sign.long), (7.0, 7.0), SIGN_COLOUR, 6.0))
    renderer = ax.figure.canvas.get_renderer()
    boxes = [m.get_window_extent(renderer) for m in marks]
    points = [ln.get_transform().transform(ln.get_xydata()) for ln in lanes]
    place_labels(ax, labels, [(b.x0, b.y0, b.x1, b.y1) for b in boxes],
                 np.concatenate(points) if points else np.empty((0, 2)))


def _legend(scene: Scene, zoomed: bool) -> list[Any]:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    present = sorted({(o.cls, o.cls_name) for o in scene.objects})
    handles: list[Any] = [Patch(facecolor=class_colour(c), label=n) for c, n in present]
    handles.append(Patch(facecolor="#ffffff", edgecolor=CIPV_EDGE, linewidth=CIPV_WIDTH,
                         label="CIPV: ring around its box"))
    handles.append(Line2D([], [], color="#000000", marker=">", markersize=5, linewidth=1.2,
                          label=f"velocity, {ARROW_S:g} s of travel"))
    handles.append(Patch(facecolor="#ffffff", edgecolor="#000000", hatch="//",
                         label="ego vehicle (drawn, not in the data)"))
    handles += [Line2D([], [], color=LINE_COLOURS["marker"], linewidth=2, label="marker, solid"),
                Line2D([], [], color=LINE_COLOURS["marker"], linewidth=2, linestyle="--",
                       label="marker, dashed"),
                Line2D([], [], color=LINE_COLOURS["border"], linewidth=2.5, label="road border"),
                Line2D([], [], color=LINE_COLOURS["centre"], linewidth=2, linestyle=":",
                       label="lane centre")]
    handles.append(Line2D([], [], marker="o", linestyle="", markerfacecolor="#ffffff",
                          markeredgecolor=SIGN_COLOUR, markeredgewidth=2.0, label="sign"))
    signs = sorted(scene.signs, key=lambda s: (not s.known, s.long))
    if not zoomed:  # one panel names the placed signs beside their marks
        signs = [s for s in signs if not s.known]
    handles += [Line2D([], [], linestyle="", label=f"  {s.name}, {s.long:.0f} m" if s.known
                       else f"  {s.name}, position unknown (not drawn)")
                for s in signs[:MAX_SIGN_NAMES]]
    if len(signs) > MAX_SIGN_NAMES:
        handles.append(Line2D([], [], linestyle="",
                              label=f"  and {len(signs) - MAX_SIGN_NAMES} more"))
    if zoomed:
        handles.append(Patch(fill=False, edgecolor="#404040", linestyle="--",
                             label="zoomed area"))
    return handles


def birdseye(scene: Scene, range_m: float | None = None, lateral_m: float | None = None) -> Any:
    forward, half_width = view_limits([scene], range_m, lateral_m)
    fig, axes = new_axes(forward, half_width, near_range([scene], half_width))
    draw_scene(axes, scene, forward, half_width)
    return fig


def animation(frames: Sequence[Scene], fps: float, range_m: float | None = None,
              lateral_m: float | None = None) -> Any:
    from matplotlib.animation import FuncAnimation

    forward, half_width = view_limits(frames, range_m, lateral_m)
    fig, axes = new_axes(forward, half_width, near_range(frames, half_width))

    def update(index: int) -> list[Any]:
        draw_scene(axes, frames[index], forward, half_width)
        return []

    return FuncAnimation(fig, update, frames=len(frames), interval=1000.0 / fps, blit=False,
                         repeat=False)
