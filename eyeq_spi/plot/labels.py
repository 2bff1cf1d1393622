"""Labels beside what they name, clear of every other mark (the bird's-eye plot's IDs and sign
names): positions around the thing are tried nearest first, the first that overlaps no mark,
lane point or earlier label wins (else the one with the fewest collisions); a label placed away
gets a leader line. All in display pixels of the fixed layout.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

PAD_PX = 3.0  # between a thing and its label
RINGS = 6  # rings of positions tried, each STEP_PX farther out
STEP_PX = 14.0
LEADER = "#707070"
_DIRECTIONS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, 1), (1, -1), (-1, -1),
               (0.5, 1), (-0.5, 1), (0.5, -1), (-0.5, -1))


@dataclass(frozen=True)
class Label:
    text: str
    at: tuple[float, float]  # data coordinates of the thing's middle
    half_px: tuple[float, float]  # the thing's half width and half height, in pixels
    colour: str = "#000000"
    fontsize: float = 7.0


Box = tuple[float, float, float, float]  # x0, y0, x1, y1 in display pixels


def _overlaps(box: Box, other: Box) -> bool:
    return box[0] < other[2] and other[0] < box[2] and box[1] < other[3] and other[1] < box[3]


def _inside(inner: Box, outer: Box) -> bool:
    return (inner[0] >= outer[0] and inner[1] >= outer[1] and inner[2] <= outer[2]
            and inner[3] <= outer[3])


def _points_in(points: Any, box: Box) -> int:
    if not len(points):
        return 0
    xs, ys = points[:, 0], points[:, 1]
    return int(np.count_nonzero((xs > box[0]) & (xs < box[2]) & (ys > box[1]) & (ys < box[3])))


def place_labels(ax: Any, labels: Sequence[Label], marks: Sequence[Box], points: Any
                 ) -> list[Any]:
    """Draw ``labels`` in ``ax`` clear of ``marks`` (boxes in pixels) and ``points`` (an N×2
    array of pixels, the lanes' sampled points); returns the text artists."""
    renderer = ax.figure.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    limits: Box = (frame.x0, frame.y0, frame.x1, frame.y1)
    to_data = ax.transData.inverted()
    taken: list[Box] = []
    texts = []
    for label in labels:
        cx, cy = ax.transData.transform(label.at)
        if not (limits[0] <= cx <= limits[2] and limits[1] <= cy <= limits[3]):
            continue  # a thing outside the panel is not named in it
        text = ax.text(*label.at, label.text, fontsize=label.fontsize, color=label.colour,
                       ha="center", va="center", zorder=8, clip_on=True)
        size = text.get_window_extent(renderer)
        w, h = size.width + 2, size.height + 2
        best: tuple[int, float, float, int] | None = None
        for ring in range(RINGS):
            for dx, dy in _DIRECTIONS:
                x = cx + dx * (label.half_px[0] + PAD_PX + w / 2 + ring * STEP_PX)
                y = cy + dy * (label.half_px[1] + PAD_PX + h / 2 + ring * STEP_PX)
                box: Box = (x - w / 2, y - h / 2, x + w / 2, y + h / 2)
                if not _inside(box, limits):
                    continue
                hits = (sum(_overlaps(box, m) for m in marks)
                        + sum(_overlaps(box, t) for t in taken) + _points_in(points, box))
                if best is None or hits < best[0]:
                    best = (hits, x, y, ring)
                if hits == 0:
                    break
            if best is not None and best[0] == 0:
                break
        if best is None:  # no room inside the panel
            text.remove()
            continue
        _, x, y, ring = best
        text.set_position(tuple(to_data.transform((x, y))))
        taken.append((x - w / 2, y - h / 2, x + w / 2, y + h / 2))
        if ring:
            ax.annotate("", xy=label.at, xytext=tuple(to_data.transform((x, y))),
                        arrowprops={"arrowstyle": "-", "color": LEADER, "linewidth": 0.6,
                                    "shrinkA": max(w, h) / 2 * 0.72, "shrinkB": 0},
                        zorder=7, annotation_clip=True)
        texts.append(text)
    return texts
