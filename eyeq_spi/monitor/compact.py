"""The monitor's screen for a small terminal (80x24 and up): the panels of the wide screen
(:mod:`eyeq_spi.monitor.view`), each folded to fit: tables in two columns, counters flowing
across the width, a panel that still does not fit folded to its title line (which keeps its
counts). Rows go first to rates, link and errors, transitions, objects, then lanes and signs;
no line is longer than the width.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rich.text import Text

from eyeq_spi.monitor.model import Snapshot
from eyeq_spi.plot.charts import short
from eyeq_spi.plot.perceived import NO_TTC, SceneObject

STATUS_STYLE = {"ok": "green", "low": "yellow", "high": "yellow", "stopped": "bold red",
                "-": "dim"}
MIN_WIDTH = 80  # two columns of 39 cells and a gap

Lines = list[Any]  # rich Text


def fit(text: str, width: int) -> str:
    """``text`` cut to ``width`` cells, an ellipsis marking the cut."""
    return text if len(text) <= width else text[:width - 1] + "\u2026"


def number(value: float | None, spec: str = "6.1f") -> str:
    return "-" if value is None or not math.isfinite(value) else format(value, spec)


def is_error(key: str) -> bool:
    return not key.endswith((" DATA", " ACK")) and key not in ("duplicate", "driver_reset")


def _ttc(obj: SceneObject) -> str:
    return NO_TTC if obj.closing_ttc is None else format(obj.closing_ttc, "4.1f")


def _two_columns(cells: list[Any], col: int, gap: int = 1) -> Lines:
    """Cells (Text of ``col`` cells each) in two columns, filled down then across."""
    rows = -(-len(cells) // 2)
    out = []
    for row in range(rows):
        left = cells[row].copy()
        left.set_length(col)
        if row + rows < len(cells):
            out.append(Text.assemble(left, " " * gap, cells[row + rows]))
        else:
            out.append(left)
    return out


def _flow(title: str, items: list[tuple[str, str]], width: int) -> Lines:
    """``title`` then ``text`` items (with their styles) separated by two spaces, wrapped at
    ``width`` between items."""
    lines: Lines = []
    cur = Text(title, style="italic")
    fresh = True  # nothing after the title or the indent yet
    for text, style in items:
        text = fit(text, width - 2)
        if cur.cell_len + 2 + len(text) > width:
            lines.append(cur)
            cur = Text("  ")
        elif not fresh:
            cur.append("  ")
        fresh = False
        cur.append(text, style=style or None)
    lines.append(cur)
    return lines


@dataclass
class Panel:
    """A panel's full lines and its one-line folded form."""

    lines: Lines
    folded: Any
    partial: Callable[[int], Lines] | None = None  # the panel in n < len(lines) lines


def _rates(snap: Snapshot, width: int) -> Panel:
    col = (width - 1) // 2
    name_w = col - 21
    head = f" {'message':<{name_w}} {'Hz':>5} {'nom.':>5} {'state':<7}"
    cells = []
    for row in snap.rates:
        hz = "-" if row.hz is None else f"{row.hz:5.1f}"
        nom = "" if row.nominal_hz is None else f"{row.nominal_hz:g}"
        cell = Text(f" {fit(short(row.name), name_w):<{name_w}} {hz:>5} {nom:>5} ")
        cell.append(f"{row.status:<7}", style=STATUS_STYLE.get(row.status, "") or None)
        cells.append(cell)
    bad = [r for r in snap.rates if r.status in ("stopped", "low", "high")]
    header = Text(fit(head + (" " + head if len(cells) > 1 else ""), width), style="bold")
    lines = [header, *_two_columns(cells, col)]
    folded = Text(f"messages {len(snap.rates)}: ", style="italic")
    folded.append(", ".join(f"{short(r.name)} {r.status}" for r in bad) or "all at nominal",
                  style="bold red" if bad else "green")
    return Panel(lines, folded)


def _link(snap: Snapshot, width: int) -> Panel:
    items = [(f"{k} {v}", "red" if v and is_error(k) else "") for k, v in
             sorted(snap.link.items())]
    items += [(f"{k} {v}", "bold red" if v else "green") for k, v in snap.errors.items()]
    stale = ", ".join(short(s) for s in snap.stale) or "none"
    items.append((f"stale streams: {stale}", "bold red" if snap.stale else "green"))
    lines = _flow("link: ", items, width)
    errors = sum(v for k, v in snap.link.items() if is_error(k)) + sum(snap.errors.values())
    folded = Text("link: ", style="italic")
    folded.append(f"{errors} errors, stale {stale}",
                  style="bold red" if errors or snap.stale else "green")
    return Panel(lines, folded)


def _transitions(snap: Snapshot, width: int) -> Panel:
    rows = [Text(fit(f" {tt:8.3f}  {a} --{ev}--> {b}", width))
            for tt, a, ev, b in snap.transitions[-6:]]
    total = snap.transitions_total
    title = Text(f"transitions (s since the start, last {len(rows)} of {total})", style="italic")

    def partial(room: int) -> Lines:
        return [Text(f"transitions (last {room - 1} of {total})", style="italic"),
                *rows[len(rows) - (room - 1):]] if room > 1 else [title]

    last = snap.transitions[-1] if snap.transitions else None
    said = f"{total}, last {last[0]:.3f} s -> {last[3]}" if last else "none"
    folded = Text("transitions: " + said, style="italic")
    return Panel([title, *rows], folded, partial)


def _objects(snap: Snapshot, width: int) -> Panel:
    col = (width - 1) // 2
    cls_w = col - 29
    head = f" {'ID':>3} {'class':<{cls_w}} {'long':>6} {'lat':>5} {'v':>5} {'TTC':>4}"
    objs = sorted(snap.scene.objects, key=lambda o: o.long)
    cells = []
    for obj in objs:
        ident = ("*" if obj.cipv else "") + str(obj.id)
        cell = Text(f" {ident:>3} {fit(obj.cls_name, cls_w):<{cls_w}} "
                    f"{number(obj.long, '6.1f'):>6} {number(obj.lat, '5.1f'):>5} "
                    f"{number(obj.v_long, '5.1f'):>5} {_ttc(obj):>4}",
                    style="bold reverse" if obj.cipv else "")
        cells.append(cell)
    count = len(objs)
    title = Text(f"objects {count} (nearest first; * CIPV; m, m/s, s)", style="italic")
    header = Text(fit(head + (" " + head if count > 1 else ""), width), style="bold")

    def partial(rows: int) -> Lines:
        shown = max(0, (rows - 2) * 2)
        if shown <= 0:
            return [folded]
        said = f"objects {count}: nearest {shown} shown, {count - shown} more (* CIPV)"
        return [Text(said, style="italic"), header, *_two_columns(cells[:shown], col)]

    cipv = next((o for o in objs if o.cipv), None)
    nearest = f": CIPV {cipv.id} at {cipv.long:.1f} m" if cipv else ""
    folded = Text(f"objects {count}" + nearest, style="italic")
    return Panel([title, header, *_two_columns(cells, col)], folded, partial)


def _road(snap: Snapshot, width: int) -> Panel:
    sc = snap.scene
    items = [(f"{ln.name} {ln.type_name or ln.kind} {number(ln.coeffs[0], '.2f')} m "
              f"{ln.start:.0f}-{ln.end:.0f} m", "") for ln in sc.lines]
    items += [(f"sign {s.name} at {s.long:.0f} m, {number(s.lat, '.1f')} m", "red")
              for s in sorted(sc.signs, key=lambda s: s.long)]
    lines = _flow(f"lanes {len(sc.lines)}, signs {len(sc.signs)}: ", items, width)
    folded = Text(f"lanes {len(sc.lines)}, signs {len(sc.signs)}", style="italic")
    return Panel(lines, folded)


PANELS = (_rates, _link, _objects, _transitions, _road)  # in the order rows are given
# the rows each panel gets before any gets more: rates and link whole, 4 objects (2 rows),
# the last 2 transitions, lanes and signs folded
FIRST_ROWS = (99, 99, 4, 3, 1)


def compact_lines(snap: Snapshot, head: Lines, width: int, height: int) -> Lines:
    """The screen in ``width`` x ``height`` cells: ``head`` (header and problem lines), then
    the panels in their screen order (rates, link, objects, lanes and signs, transitions),
    each as full as the rows left allow."""
    width = max(width, MIN_WIDTH)
    panels = [make(snap, width) for make in PANELS]
    left = height - len(head) - len(panels)  # every panel has at least its folded line
    shown: list[Lines] = [[p.folded] for p in panels]
    for cap in (FIRST_ROWS, (10**6,) * len(panels)):  # first a share each, then the rest
        for index, panel in enumerate(panels):  # unfold in priority order while rows are left
            want = min(len(panel.lines), cap[index])
            extra = want - len(shown[index])
            if extra <= 0 or left <= 0:
                continue
            if want == len(panel.lines) and extra <= left:
                shown[index], left = panel.lines, left - extra
            elif panel.partial is not None:
                part = panel.partial(min(want, len(shown[index]) + left))
                if len(part) > len(shown[index]):
                    left -= len(part) - len(shown[index])
                    shown[index] = part
    rates, link, objects, transitions, road = shown
    return [*head, *rates, *link, *objects, *road, *transitions]
