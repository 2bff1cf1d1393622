"""A :class:`Snapshot` drawn with rich: header, rates, link and errors, objects, lanes and
signs, state transitions. Pure: the same snapshot always gives the same screen."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from eyeq_spi.errors import EyeqError
from eyeq_spi.monitor.model import Snapshot
from eyeq_spi.plot.charts import short

STATUS_STYLE = {"ok": "green", "low": "yellow", "high": "yellow", "stopped": "bold red",
                "-": "dim"}
GOOD_STATES = ("RUNNING_VISION", "RUNNING_TAC", "RUNNING_SPC", "DV", "Running Vision")


class MonitorError(EyeqError):
    """The monitor cannot run (missing library, bad option)."""


@dataclass
class RichModules:
    Console: Any
    Live: Any
    Table: Any
    Text: Any
    Group: Any
    box: Any


_RICH: RichModules | None = None


def rich_modules() -> RichModules:
    global _RICH
    if _RICH is None:
        try:
            from rich import box
            from rich.console import Console, Group
            from rich.live import Live
            from rich.table import Table
            from rich.text import Text
        except ImportError:
            raise MonitorError("the monitor needs rich: pip install 'eyeq-spi[monitor]'"
                               ) from None
        _RICH = RichModules(Console, Live, Table, Text, Group, box)
    return _RICH


def _rich() -> RichModules:
    return rich_modules()


Col = tuple[str, int, str]  # header, width, justify


def _table(title: str, cols: list[Col]) -> Any:
    """Fixed column widths: rich then never measures cells, which keeps a redraw cheap."""
    r = _rich()
    t = r.Table(title=title, title_justify="left", box=r.box.SIMPLE_HEAD, pad_edge=False)
    for head, width, just in cols:
        t.add_column(head, width=width + 1, justify=just, no_wrap=True, overflow="ellipsis")
    return t


def _width(cols: list[Col]) -> int:
    return sum(w + 1 for _, w, _ in cols) + 2 * (len(cols) - 1)


RATE_COLS: list[Col] = [("message", 22, "left"), ("count", 7, "right"), ("Hz", 6, "right"),
                        ("nominal", 7, "right"), ("", 7, "left")]
LINK_COLS: list[Col] = [("counter", 24, "left"), ("value", 10, "right")]
OBJECT_COLS: list[Col] = [("ID", 3, "right"), ("class", 22, "left"), ("long m", 7, "right"),
                          ("lat m", 6, "right"), ("vlong m/s", 9, "right"),
                          ("vlat", 5, "right"), ("TTC s", 5, "right")]
ROAD_COLS: list[Col] = [("line / sign", 20, "left"), ("type", 16, "left"),
                        ("lat m", 6, "right"), ("range m", 7, "right")]
TRANSITION_COLS: list[Col] = [("t s", 9, "right"), ("from", 18, "left"), ("event", 22, "left"),
                              ("to", 18, "left")]


def _rates(snap: Snapshot) -> Any:
    r = _rich()
    t = _table("messages (Hz over 2 s)", RATE_COLS)
    for row in snap.rates:
        hz = "-" if row.hz is None else f"{row.hz:5.1f}"
        nom = "" if row.nominal_hz is None else f"{row.nominal_hz:g}"
        t.add_row(short(row.name), str(row.count), hz, nom,
                  r.Text(row.status, style=STATUS_STYLE.get(row.status, "")))
    return t


def _link(snap: Snapshot) -> Any:
    r = _rich()
    t = _table("link", LINK_COLS)
    for k, v in sorted(snap.link.items()):
        t.add_row(k, r.Text(str(v), style="red" if v and _is_error(k) else ""))
    for k, v in snap.errors.items():
        t.add_row(k, r.Text(str(v), style="bold red" if v else "green"))
    t.add_row("stale streams", r.Text(", ".join(short(s) for s in snap.stale) or "none",
                                      style="bold red" if snap.stale else "green"))
    return t


def _is_error(key: str) -> bool:
    return not key.endswith((" DATA", " ACK")) and key not in ("duplicate", "driver_reset")


def _fmt(v: float | None, spec: str = "6.1f") -> str:
    return "-" if v is None or not math.isfinite(v) else format(v, spec)


def _objects(snap: Snapshot) -> Any:
    t = _table(f"objects ({len(snap.scene.objects)})", OBJECT_COLS)
    for o in sorted(snap.scene.objects, key=lambda o: o.long):
        style = "bold reverse" if o.cipv else ""
        t.add_row(str(o.id), o.cls_name + (" CIPV" if o.cipv else ""), _fmt(o.long),
                  _fmt(o.lat, "5.1f"), _fmt(o.v_long, "5.1f"), _fmt(o.v_lat, "4.1f"),
                  _fmt(o.ttc, "4.1f"), style=style)
    return t


def _road(snap: Snapshot) -> Any:
    r = _rich()
    t = _table(f"lanes ({len(snap.scene.lines)}) and signs ({len(snap.scene.signs)})",
               ROAD_COLS)
    for ln in snap.scene.lines:
        t.add_row(ln.name, ln.type_name or ln.kind, _fmt(ln.coeffs[0], "5.2f"),
                  f"{ln.start:.0f}-{ln.end:.0f}")
    for s in sorted(snap.scene.signs, key=lambda s: s.long):
        t.add_row(r.Text("sign", style="red"), s.name, _fmt(s.lat, "5.1f"), f"{s.long:.0f}")
    return t


def _transitions(snap: Snapshot) -> Any:
    t = _table("transitions", TRANSITION_COLS)
    for tt, a, ev, b in snap.transitions[-6:]:
        t.add_row(f"{tt:8.3f}", a, ev, b)
    return t


def _side_by_side(left: Any, lw: int, right: Any, rw: int) -> Any:
    g = _rich().Table.grid(padding=(0, 3))
    g.add_column(width=lw + 1)
    g.add_column(width=rw + 1)
    g.add_row(left, right)
    return g


def render(snap: Snapshot) -> Any:
    r = _rich()
    state_style = "bold green" if snap.state in GOOD_STATES else "bold yellow"
    head = r.Text.assemble(
        ("eyeq-spi monitor ", "bold"), (snap.source, "cyan"), f"   t {snap.now:8.2f} s   ",
        (f"{snap.state_label}: ", ""), (snap.state, state_style),
        ("   finished" if snap.done else "", "dim"))
    parts: list[Any] = [head]
    if snap.problem:
        parts.append(r.Text(f"problem: {snap.problem}", style="bold red"))
    parts += [_side_by_side(_rates(snap), _width(RATE_COLS), _link(snap), _width(LINK_COLS)),
              _side_by_side(_objects(snap), _width(OBJECT_COLS), _road(snap),
                            _width(ROAD_COLS)),
              _transitions(snap)]
    return r.Group(*parts)
