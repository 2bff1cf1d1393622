"""A :class:`Snapshot` drawn with rich: header, rates, link and errors, objects, lanes and
signs, state transitions, as lines of rich Text in fixed columns (cheap to redraw).
Pure: the same snapshot always gives the same screen."""

from __future__ import annotations

from typing import Any

from rich.console import Console, Group
from rich.live import Live
from rich.text import Text

from eyeq_spi.monitor.compact import STATUS_STYLE, compact_lines, fit, is_error, number
from eyeq_spi.monitor.model import Snapshot
from eyeq_spi.plot.charts import short
from eyeq_spi.plot.figures import plural, write_file
from eyeq_spi.plot.perceived import NO_TTC

GOOD_STATES = ("RUNNING_VISION", "RUNNING_TAC", "RUNNING_SPC", "DV", "Running Vision")


Col = tuple[str, int, str]  # header, width, justify
Cell = tuple[str, str]  # text, style
GAP = "  "  # between columns
SIDE_GAP = "   "  # between two blocks side by side


def _cell(text: str, width: int, just: str) -> str:
    text = fit(text, width)
    return text.rjust(width) if just == "right" else text.ljust(width)


def _width(cols: list[Col]) -> int:
    return 1 + sum(w for _, w, _ in cols) + len(GAP) * (len(cols) - 1)


def _block(title: str, cols: list[Col], rows: list[tuple[list[Cell], str]]) -> list[Any]:
    """A table as lines of rich Text: title, bold header, rule, one line per row.

    Columns have fixed widths and each row is one Text with a span per styled cell. A rich
    ``Table`` measures, pads and wraps every cell on every redraw (about 15 ms of CPU for this
    screen); lines of Text cost rich about a tenth of that (tools/bench_monitor.py)."""
    head = " " + GAP.join(_cell(h, w, j) for h, w, j in cols)
    lines = [Text(title, style="italic"), Text(head, style="bold"),
             Text(" " + "\u2500" * (_width(cols) - 1), style="dim")]
    for cells, row_style in rows:
        line = Text(" ", style=row_style)
        for index, ((text, style), (_, width, justify)) in enumerate(zip(cells, cols, strict=True)):
            if index:
                line.append(GAP)
            line.append(_cell(text, width, justify), style=style or None)
        lines.append(line)
    return lines


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


def _rates(snap: Snapshot) -> list[Any]:
    rows = []
    for row in snap.rates:
        hz = "-" if row.hz is None else f"{row.hz:5.1f}"
        nom = "" if row.nominal_hz is None else f"{row.nominal_hz:g}"
        rows.append(([(short(row.name), ""), (str(row.count), ""), (hz, ""), (nom, ""),
                      (row.status, STATUS_STYLE.get(row.status, ""))], ""))
    # a gap (a silence over 4 median periods) is left out of the rate, not averaged in
    gaps = sum(row.gaps for row in snap.rates)
    title = "messages (Hz over 2 s" + (f"; {plural(gaps, 'gap')} left out)" if gaps else ")")
    return _block(title, RATE_COLS, rows)


def _link(snap: Snapshot) -> list[Any]:
    rows = [([(k, ""), (str(v), "red" if v and is_error(k) else "")], "")
            for k, v in sorted(snap.link.items())]
    rows += [([(k, ""), (str(v), "bold red" if v else "green")], "")
             for k, v in snap.errors.items()]
    stale = ", ".join(short(s) for s in snap.stale) or "none"
    rows.append(([("stale streams", ""), (stale, "bold red" if snap.stale else "green")], ""))
    return _block("link", LINK_COLS, rows)


def _objects(snap: Snapshot) -> list[Any]:
    rows = []
    for obj in sorted(snap.scene.objects, key=lambda o: o.long):
        cells = [str(obj.id), obj.cls_name + (" CIPV" if obj.cipv else ""), number(obj.long),
                 number(obj.lat, "5.1f"), number(obj.v_long, "5.1f"), number(obj.v_lat, "4.1f"),
                 NO_TTC if obj.closing_ttc is None else number(obj.closing_ttc, "4.1f")]
        rows.append(([(c, "") for c in cells], "bold reverse" if obj.cipv else ""))
    return _block(f"objects ({len(snap.scene.objects)})", OBJECT_COLS, rows)


def _road(snap: Snapshot) -> list[Any]:
    rows = [([(ln.name, ""), (ln.type_name or ln.kind, ""), (number(ln.coeffs[0], "5.2f"), ""),
              (f"{ln.start:.0f}-{ln.end:.0f}", "")], "") for ln in snap.scene.lines]
    rows += [([("sign", "red"), (s.name, ""), (number(s.lat, "5.1f"), ""), (f"{s.long:.0f}", "")],
              "") for s in sorted(snap.scene.signs, key=lambda s: s.long)]
    return _block(f"lanes ({len(snap.scene.lines)}) and signs ({len(snap.scene.signs)})",
                  ROAD_COLS, rows)


def _transitions(snap: Snapshot) -> list[Any]:
    rows = [([(f"{tt:8.3f}", ""), (a, ""), (ev, ""), (b, "")], "")
            for tt, a, ev, b in snap.transitions[-6:]]
    total = snap.transitions_total
    title = "transitions" if total <= len(rows) else f"transitions (last {len(rows)} of {total})"
    return _block(title, TRANSITION_COLS, rows)


def _pair(left: list[Any], lw: int, right: list[Any], rw: int, width: int | None
          ) -> list[Any]:
    """Two blocks side by side, or one above the other when the terminal is too narrow."""
    if width is not None and lw + len(SIDE_GAP) + rw > width:
        return [*left, Text(), *right]
    out = []
    for row in range(max(len(left), len(right))):
        line = left[row].copy() if row < len(left) else Text()
        line.set_length(lw)
        out.append(Text.assemble(line, SIDE_GAP, right[row]) if row < len(right) else line)
    return out


def _head(snap: Snapshot, width: int | None) -> list[Any]:
    """The header (source, time since the start, state) and the problem, if any."""
    state_style = "bold green" if snap.state in GOOD_STATES else "bold yellow"
    state = Text.assemble((f"{snap.state_label}: ", ""), (snap.state, state_style),
                          ("   finished" if snap.done else "", "dim"))
    when = f"   t {snap.now:8.2f} s   "
    source, title = snap.source, "eyeq-spi monitor "
    if width is not None:  # the state and time are kept whole; the title, then the source give
        if len(title) + len(source) + len(when) + state.cell_len > width:
            title, when = "", f"  t {snap.now:.2f} s  "
        room = width - len(title) - len(when) - state.cell_len
        if room < len(source):
            source = source[:max(1, room) - 1] + "\u2026" if room > 1 else ""
    head = [Text.assemble((title, "bold"), (source, "cyan"), when, state)]
    if snap.problem:
        head.append(Text(f"problem: {snap.problem}", style="bold red"))
    return head


def screen_lines(snap: Snapshot, width: int | None = None,
                 height: int | None = None) -> list[Any]:
    """The screen as lines of rich Text. Blocks stand side by side, or stacked where the
    terminal (``width`` columns) is too narrow for two; where that does not fit ``height``
    rows either, the compact screen (:mod:`eyeq_spi.monitor.compact`) folds the panels.
    Lines never wrap."""
    lines = _head(snap, width)
    head = list(lines)
    lines += [Text(), *_pair(_rates(snap), _width(RATE_COLS), _link(snap), _width(LINK_COLS),
                             width), Text(),
              *_pair(_objects(snap), _width(OBJECT_COLS), _road(snap), _width(ROAD_COLS),
                     width), Text(),
              *_transitions(snap)]
    too_wide = width is not None and max(t.cell_len for t in lines) > width
    # the last row is the cursor's: a screen of ``height`` lines scrolls its title away
    if height is not None and width is not None and (len(lines) > height - 1 or too_wide):
        lines = compact_lines(snap, head, width, height - 1)  # the cursor's line
    for line in lines:
        line.no_wrap, line.overflow, line.end = True, "crop", "\n"
    return lines


def render(snap: Snapshot, width: int | None = None, height: int | None = None) -> Any:
    return Group(*screen_lines(snap, width, height))


def new_live(console: Any) -> Any:
    """A rich ``Live`` redrawn only when asked, cropped to the terminal."""
    return Live(console=console, auto_refresh=False, transient=False, vertical_overflow="crop",
                redirect_stdout=False, redirect_stderr=False)


def print_whole(console: Any, lines: list[Any]) -> None:
    """``lines`` printed once, as wide as they are (a pipe: the console's default is 80)."""
    console.width = max(console.width, *(t.cell_len for t in lines))
    console.print(Group(*lines))


def save_lines(lines: list[Any], path: str, title: str) -> None:
    """Rich lines as an SVG picture, an HTML page or plain text (by ``path``'s suffix), as
    wide as the widest line; ``OutputError`` when the file cannot be written."""
    import io

    con = Console(file=io.StringIO(), record=True, force_terminal=True,
                  color_system="truecolor", width=max(t.cell_len for t in lines))
    con.print(Group(*lines))
    suffix = path.lower().rsplit(".", 1)[-1]
    write_file(path, con.export_svg(title=title) if suffix == "svg" else
               con.export_html() if suffix == "html" else con.export_text())
