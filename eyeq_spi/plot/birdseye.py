"""The ego vehicle's view from above (``eyeq-spi plot --birdseye``).

Lateral goes left-to-right as the driver sees it (``lat`` positive = left, so the x axis is
inverted), longitudinal goes up. Both axes have the same scale (a metre is as long across as
along), so boxes and lanes keep their true shape: the whole view is a tall strip, and where
that strip is narrow a second panel zooms on the near range at a larger, still equal, scale.
The layout is fixed (figure size, dpi, and the rectangles :func:`layout` computes from the view
limits) so a pixel of the written PNG maps back to metres; the tests rely on that.

- an object is a box ``width`` wide and ``length`` long whose rear middle is at
  (``longDistance``, ``latDistance``) (§13.2.5.3: distances are "to the middle of the Rear Left
  and Rear Right corners"), turned by ``heading``, filled with its class's colour, labelled with
  its ID; the CIPV gets a thick outline;
- the velocity arrow shows where the absolute velocity carries the object in ARROW_S seconds;
- lines are drawn from their polynomials over ``[startRange, endRange]``;
- a sign is a ring at its reported position, with its type's name.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from eyeq_spi.plot.figures import new_figure, plural
from eyeq_spi.plot.perceived import Scene, SceneLine, SceneObject

FIGSIZE = (10.0, 9.0)  # inches
DPI = 100
BOTTOM, HEIGHT = 0.06, 0.86  # of the figure: where the panels stand
LEFT = 0.07  # the whole view's left edge
ZOOM_W = 0.36  # the zoom panel's width, when there is one
GAP = 0.07  # between the panels (room for the zoom's axis labels)
LEGEND_W = 0.2  # kept free on the right for the legend
MAX_SIGN_NAMES = 8  # signs named in the legend (the whole view is too narrow for labels)
REAR_M = 10.0  # metres shown behind the ego vehicle's origin
ARROW_S = 0.5  # velocity arrows show 0.5 s of travel
EGO = (4.5, 1.8)  # length, width of the ego vehicle drawn behind the origin (not in the data)
BACKGROUND = "#f2f2f2"
CIPV_EDGE = "#000000"
LINE_COLOURS = {"marker": "#50509a", "border": "#a0522d", "centre": "#2ca02c"}
SIGN_COLOUR = "#d00000"
_TAB10 = ("#1f77b4", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
          "#17becf")


def class_colour(cls: int) -> str:
    """object_classification value -> fill colour (car blue, truck orange, ...)."""
    return _TAB10[cls % len(_TAB10)]


def view_limits(scenes: Sequence[Scene], range_m: float | None = None,
                lateral_m: float | None = None) -> tuple[float, float]:
    """(forward range, lateral half-width) in metres: given, or fitted to what is drawn."""
    if range_m is None:
        far = 40.0
        for sc in scenes:
            far = max(far, *(o.long + o.length for o in sc.objects), *(ln.end for ln in sc.lines),
                      *(s.long for s in sc.signs), 0.0)
        range_m = min(250.0, math.ceil((far + 5.0) / 10.0) * 10.0)
    if lateral_m is None:
        wide = 10.0
        for sc in scenes:
            wide = max(wide, *(abs(o.lat) + o.width for o in sc.objects),
                       *(abs(s.lat) + 1.0 for s in sc.signs), 0.0)
            for ln in sc.lines:
                wide = max(wide, abs(ln.lateral(ln.start)), abs(ln.lateral(ln.end)))
        lateral_m = min(100.0, math.ceil(wide + 2.0))
    return range_m, lateral_m


def box_corners(o: SceneObject) -> list[tuple[float, float]]:
    """The box's corners as (lat, long), starting at the rear right, counter-clockwise."""
    ch, sh = math.cos(o.heading), math.sin(o.heading)
    fwd = (ch, sh)  # (long, lat) of the object's forward axis
    left = (-sh, ch)
    hw = o.width / 2.0
    pts = []
    for along, side in ((0.0, -hw), (o.length, -hw), (o.length, hw), (0.0, hw)):
        lo = o.long + along * fwd[0] + side * left[0]
        la = o.lat + along * fwd[1] + side * left[1]
        pts.append((la, lo))
    return pts


def line_points(ln: SceneLine, step: float = 0.5) -> tuple[list[float], list[float]]:
    n = max(2, int((ln.end - ln.start) / step) + 1)
    xs = [ln.start + (ln.end - ln.start) * i / (n - 1) for i in range(n)]
    return [ln.lateral(x) for x in xs], xs


Rect = tuple[float, float, float, float]  # left, bottom, width, height (figure fractions)


def layout(range_m: float, lateral_m: float) -> tuple[Rect, Rect | None, float]:
    """The whole view's rectangle, the zoom panel's (None when the whole view is wide enough
    to read) and the zoom's forward range in metres. Both panels have equal scales: the
    rectangles' pixel sizes are in the ratio of the metres they show."""
    fw, fh = FIGSIZE[0] * DPI, FIGSIZE[1] * DPI
    span = range_m + REAR_M
    room = (1.0 - LEFT - LEGEND_W) * fw  # pixels across for the whole view alone
    ppm = min(HEIGHT * fh / span, room / (2 * lateral_m))  # pixels per metre
    main: Rect = (LEFT, BOTTOM + HEIGHT - span * ppm / fh, 2 * lateral_m * ppm / fw,
                  span * ppm / fh)
    zoom_ppm = min(ZOOM_W * fw / (2 * lateral_m), HEIGHT * fh / (REAR_M + 10.0))
    zoom_range = HEIGHT * fh / zoom_ppm - REAR_M
    if zoom_ppm < 1.5 * ppm or zoom_range >= range_m:
        return main, None, range_m
    zoom: Rect = (LEFT + main[2] + GAP, BOTTOM, 2 * lateral_m * zoom_ppm / fw, HEIGHT)
    return main, zoom, zoom_range


def new_axes(range_m: float, lateral_m: float) -> tuple[Any, list[Any]]:
    """The figure and its panels: the whole view, and the zoom when :func:`layout` has one."""
    fig = new_figure(*FIGSIZE, DPI)
    main, zoom, zoom_range = layout(range_m, lateral_m)
    axes = [fig.add_axes(main)]
    if zoom is not None:
        axes.append(fig.add_axes(zoom))
    for k, ax in enumerate(axes):
        _frame(ax, range_m if k == 0 else zoom_range, lateral_m)
    return fig, axes


def _frame(ax: Any, range_m: float, lateral_m: float) -> None:
    ax.set_facecolor(BACKGROUND)
    ax.set_xlim(lateral_m, -lateral_m)  # left of the car on the left
    ax.set_ylim(-REAR_M, range_m)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("lateral (m, left +)")
    ax.set_ylabel("longitudinal (m)")
    ax.grid(True, color="#dddddd", linewidth=0.5, zorder=0)


def _label_side(lat: float, half: float) -> tuple[float, str]:
    """Where a label goes beside something at ``lat`` that is ``half`` wide: on the side
    towards the middle of the view, so it stays inside the axes."""
    if lat >= 0:  # left half of the view (x inverted): the label runs to the right
        return lat - half - 0.4, "left"
    return lat + half + 0.4, "right"


def draw_scene(axes: Any, scene: Scene, range_m: float, lateral_m: float,
               title: str | None = None) -> None:
    """Draw ``scene`` into each panel of ``axes`` (one axes or the list from
    :func:`new_axes`); the legend and title go with the figure."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import FancyArrowPatch, Patch, Polygon, Rectangle

    axes = axes if isinstance(axes, list) else [axes]
    zoom_range = range_m
    for k, ax in enumerate(axes):
        if k:
            zoom_range = ax.get_ylim()[1]
        ax.clear()
        _frame(ax, range_m if k == 0 else zoom_range, lateral_m)
        length, width = EGO
        ax.add_patch(Rectangle((-width / 2, -length), width, length, facecolor="#ffffff",
                               edgecolor="#000000", hatch="//", linewidth=1.0, zorder=2))
        for ln in scene.lines:
            lat, lon = line_points(ln)
            style = "--" if ln.type_name == "DASHED" else (":" if ln.kind == "centre" else "-")
            ax.plot(lat, lon, style, color=LINE_COLOURS[ln.kind],
                    linewidth=2.5 if ln.kind == "border" else 2.0, zorder=3)
        for o in scene.objects:
            cx = o.lat + math.sin(o.heading) * o.length / 2
            cy = o.long + math.cos(o.heading) * o.length / 2
            if o.v_long or o.v_lat:  # drawn under the box: only the part outside it shows
                ax.add_patch(FancyArrowPatch(
                    (cx, cy), (cx + o.v_lat * ARROW_S, cy + o.v_long * ARROW_S), zorder=4,
                    arrowstyle="-|>", mutation_scale=10, color="#000000", linewidth=1.2))
            ax.add_patch(Polygon(box_corners(o), closed=True, facecolor=class_colour(o.cls),
                                 edgecolor=CIPV_EDGE if o.cipv else "#202020",
                                 linewidth=3.0 if o.cipv else 0.6, zorder=5))
            x, ha = _label_side(o.lat, o.width / 2)
            ax.text(x, o.long + o.length / 2, f"{o.id}" + (" CIPV" if o.cipv else ""),
                    fontsize=7, ha=ha, va="center", zorder=6, clip_on=True)
        for s in scene.signs:
            ax.plot([s.lat], [s.long], "o", markersize=9, markerfacecolor="#ffffff",
                    markeredgecolor=SIGN_COLOUR, markeredgewidth=2.0, zorder=5)
            if k or len(axes) == 1:  # the narrow whole view has no room: the legend names them
                x, ha = _label_side(s.lat, 0.6)
                ax.text(x, s.long, s.name, fontsize=6, color=SIGN_COLOUR, ha=ha, va="center",
                        zorder=6, clip_on=True)
    if len(axes) > 1:  # where the zoom is, on the whole view
        axes[0].add_patch(Rectangle((-lateral_m, -REAR_M), 2 * lateral_m, zoom_range + REAR_M,
                                    fill=False, edgecolor="#404040", linestyle="--",
                                    linewidth=1.0, zorder=7))
        axes[1].set_title(f"near range, {zoom_range:.0f} m (zoom)", fontsize=9)
        axes[0].set_title("whole view", fontsize=9)
    present = sorted({(o.cls, o.cls_name) for o in scene.objects})
    handles: list[Any] = [Patch(facecolor=class_colour(c), label=n) for c, n in present]
    handles.append(Patch(facecolor="#ffffff", edgecolor=CIPV_EDGE, linewidth=3.0, label="CIPV"))
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
    if len(axes) > 1:
        signs = sorted(scene.signs, key=lambda s: s.long)
        handles += [Line2D([], [], linestyle="", label=f"  {s.name}, {s.long:.0f} m")
                    for s in signs[:MAX_SIGN_NAMES]]
        if len(signs) > MAX_SIGN_NAMES:
            handles.append(Line2D([], [], linestyle="",
                                  label=f"  and {len(signs) - MAX_SIGN_NAMES} more"))
    if len(axes) > 1:
        handles.append(Patch(fill=False, edgecolor="#404040", linestyle="--",
                             label="zoomed area"))
    fig = axes[0].figure
    for old in list(fig.legends):
        old.remove()
    fig.legend(handles=handles, loc="upper right", bbox_to_anchor=(0.995, BOTTOM + HEIGHT),
               fontsize=8)
    when = "end of capture" if scene.time is None else f"t = {scene.time:.2f} s"
    fig.suptitle(title or f"{when} (s since the capture's first record): "
                 f"{plural(len(scene.objects), 'object')}, {plural(len(scene.lines), 'line')}, "
                 f"{plural(len(scene.signs), 'sign')}; equal scales", fontsize=10)


def birdseye(scene: Scene, range_m: float | None = None, lateral_m: float | None = None) -> Any:
    r, w = view_limits([scene], range_m, lateral_m)
    fig, axes = new_axes(r, w)
    draw_scene(axes, scene, r, w)
    return fig


def animation(frames: Sequence[Scene], fps: float, range_m: float | None = None,
              lateral_m: float | None = None) -> Any:
    from matplotlib.animation import FuncAnimation

    r, w = view_limits(frames, range_m, lateral_m)
    fig, axes = new_axes(r, w)

    def update(i: int) -> list[Any]:
        draw_scene(axes, frames[i], r, w)
        return []

    return FuncAnimation(fig, update, frames=len(frames), interval=1000.0 / fps, blit=False,
                         repeat=False)
