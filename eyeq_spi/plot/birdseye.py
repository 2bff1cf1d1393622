"""The ego vehicle's view from above (``eyeq-spi plot --birdseye``).

Lateral goes left-to-right as the driver sees it (``lat`` positive = left, so the x axis is
inverted), longitudinal goes up. The layout is fixed (figure size, dpi, axes rectangle, view
limits from :func:`view_limits`) so a pixel of the written PNG maps back to metres; the tests
rely on that.

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

from eyeq_spi.plot.output import new_figure
from eyeq_spi.plot.scene import Scene, SceneLine, SceneObject

FIGSIZE = (7.0, 9.0)  # inches
DPI = 100
AXES_RECT = (0.09, 0.06, 0.62, 0.88)  # left, bottom, width, height (figure fractions)
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


def new_axes(range_m: float, lateral_m: float) -> tuple[Any, Any]:
    fig = new_figure(*FIGSIZE, DPI)
    ax = fig.add_axes(AXES_RECT)
    _frame(ax, range_m, lateral_m)
    return fig, ax


def _frame(ax: Any, range_m: float, lateral_m: float) -> None:
    ax.set_facecolor(BACKGROUND)
    ax.set_xlim(lateral_m, -lateral_m)  # left of the car on the left
    ax.set_ylim(-REAR_M, range_m)
    ax.set_xlabel("lateral (m, left +)")
    ax.set_ylabel("longitudinal (m)")
    ax.grid(True, color="#dddddd", linewidth=0.5, zorder=0)


def draw_scene(ax: Any, scene: Scene, range_m: float, lateral_m: float,
               title: str | None = None) -> None:
    from matplotlib.lines import Line2D
    from matplotlib.patches import FancyArrowPatch, Patch, Polygon, Rectangle

    ax.clear()
    _frame(ax, range_m, lateral_m)
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
        label = f"{o.id}" + (" CIPV" if o.cipv else "")
        ax.text(o.lat - o.width / 2 - 0.4, o.long + o.length / 2, label, fontsize=7,
                ha="left", va="center", zorder=6, clip_on=True)
    for s in scene.signs:
        ax.plot([s.lat], [s.long], "o", markersize=9, markerfacecolor="#ffffff",
                markeredgecolor=SIGN_COLOUR, markeredgewidth=2.0, zorder=5)
        ax.text(s.lat - 1.0, s.long, s.name, fontsize=6, color=SIGN_COLOUR, ha="left",
                va="center", zorder=6, clip_on=True)
    present = sorted({(o.cls, o.cls_name) for o in scene.objects})
    handles: list[Any] = [Patch(facecolor=class_colour(c), label=n) for c, n in present]
    handles.append(Patch(facecolor="#ffffff", edgecolor=CIPV_EDGE, linewidth=3.0, label="CIPV"))
    handles += [Line2D([], [], color=LINE_COLOURS[k], label=k, linewidth=2)
                for k in ("marker", "border", "centre")]
    handles.append(Line2D([], [], marker="o", linestyle="", markerfacecolor="#ffffff",
                          markeredgecolor=SIGN_COLOUR, label="sign"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8,
              title=f"arrow: {ARROW_S:g} s of velocity", title_fontsize=7)
    when = "end of capture" if scene.time is None else f"t = {scene.time:.2f} s"
    ax.set_title(title or f"{when}: {len(scene.objects)} objects, {len(scene.lines)} lines, "
                 f"{len(scene.signs)} signs", fontsize=10)


def birdseye(scene: Scene, range_m: float | None = None, lateral_m: float | None = None) -> Any:
    r, w = view_limits([scene], range_m, lateral_m)
    fig, ax = new_axes(r, w)
    draw_scene(ax, scene, r, w)
    return fig


def animation(frames: Sequence[Scene], fps: float, range_m: float | None = None,
              lateral_m: float | None = None) -> Any:
    from matplotlib.animation import FuncAnimation

    r, w = view_limits(frames, range_m, lateral_m)
    fig, ax = new_axes(r, w)

    def update(i: int) -> list[Any]:
        draw_scene(ax, frames[i], r, w)
        return []

    return FuncAnimation(fig, update, frames=len(frames), interval=1000.0 / fps, blit=False,
                         repeat=False)
