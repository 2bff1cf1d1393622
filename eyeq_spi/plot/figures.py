"""matplotlib loading and writing figures: PNG, SVG, or a self-contained HTML file; animations
as GIF (Pillow, a matplotlib dependency) or an HTML player (``Animation.to_jshtml``)."""

from __future__ import annotations

import html
import io
from pathlib import Path
from typing import Any

from eyeq_spi.errors import MissingExtra, OutputError, UsageError

STILL = (".png", ".svg", ".html")
MOVING = (".gif", ".html")


def mpl() -> Any:
    """matplotlib with the Agg backend (no display needed), or a typed error with the hint."""
    try:
        import matplotlib
    except ImportError:
        raise MissingExtra("plot", "plots need matplotlib") from None
    matplotlib.use("Agg", force=True)
    return matplotlib


def plural(count: int, word: str) -> str:
    """``1 sign``, ``3 signs`` (the words the plots use take an s)."""
    return f"{count} {word}" if count == 1 else f"{count} {word}s"


def new_figure(width_in: float, height_in: float, dpi: int) -> Any:
    mpl()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def check_output(path: str, animated: bool) -> str:
    suffix = Path(path).suffix.lower()
    allowed = MOVING if animated else STILL
    if suffix not in allowed:
        raise UsageError(f"{path}: output must end in {', '.join(allowed)}")
    return suffix


def _page(title: str, body: str) -> str:
    return ("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>"
            f"{html.escape(title)}</title></head>\n<body style=\"margin:0\">\n{body}\n"
            "</body></html>\n")


def write_file(path: str, data: bytes | str) -> None:
    """``data`` into the file ``path`` (text as UTF-8), or an ``OutputError`` saying why not."""
    try:
        if isinstance(data, str):
            Path(path).write_text(data, encoding="utf-8")
        else:
            Path(path).write_bytes(data)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None


def save_figure(fig: Any, path: str, title: str) -> None:
    suffix = check_output(path, animated=False)
    buf = io.BytesIO()
    # no bbox_inches="tight": pixel positions stay where the fixed layout puts them
    # SVG metadata would name matplotlib's web site: an HTML page holds no web address
    fig.savefig(buf, format="svg" if suffix != ".png" else "png", dpi=fig.dpi,
                metadata={"Creator": None, "Date": None, "Format": None, "Type": None}
                if suffix != ".png" else {"Software": "eyeq-spi"})
    if suffix == ".html":
        svg = buf.getvalue().decode("utf-8")
        svg = svg[svg.find("<svg"):]  # inline: drop the XML prolog and doctype
        write_file(path, _page(title, svg))
    else:
        write_file(path, buf.getvalue())


def save_animation(anim: Any, path: str, fps: float, title: str) -> None:
    suffix = check_output(path, animated=True)
    if suffix == ".gif":
        from matplotlib.animation import PillowWriter

        try:
            anim.save(path, writer=PillowWriter(fps=max(1, round(fps))))
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    else:
        write_file(path, _page(title, offline(anim.to_jshtml(fps=fps, default_mode="once"))))


# matplotlib's HTML player draws its buttons with Font Awesome from a CDN; these are the same
# buttons as plain characters, so the page needs nothing from the network
_ICONS = {"fa fa-minus": "\u2212", "fa fa-fast-backward": "\u23ee",
          "fa fa-step-backward": "\u23f4\u2758", "fa fa-play fa-flip-horizontal": "\u25c0",
          "fa fa-pause": "\u23f8", "fa fa-play": "\u25b6", "fa fa-step-forward": "\u2758\u23f5",
          "fa fa-fast-forward": "\u23ed", "fa fa-plus": "+"}


def offline(page: str) -> str:
    """``page`` without its stylesheet links (the player's icon font) and with the icons as
    characters."""
    import re

    page = re.sub(r"<link\b[^>]*>", "", page, flags=re.S)
    return re.sub(r'<i class="(fa [^"]*)"></i>',
                  lambda m: _ICONS.get(m.group(1), m.group(1).split()[-1]), page)
