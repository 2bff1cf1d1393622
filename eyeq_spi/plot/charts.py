"""Stream timing (``--timing``) and link behaviour (``--link``) over a capture."""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Sequence
from typing import Any

from eyeq_spi.errors import InputError
from eyeq_spi.plot.collect import GAP_PERIODS, Collected, Stream
from eyeq_spi.plot.figures import new_figure, plural
from eyeq_spi.stream_rate import stream_rate

GAP_COLOUR = "#d62728"
BAND_COLOUR = "#2ca02c"
DOT_COLOUR = "#1f77b4"
# the origin of every time axis: the capture's first timestamped record, as dissect's lines
TIME_LABEL = "s since the capture's first transfer (as eyeq-spi dissect)"
# series of one panel: each its own colour and style, the first drawn widest so that series
# with equal values show as nested stripes instead of hiding one another
SERIES_STYLES = (("#1f77b4", "-", 5.0), ("#ff7f0e", "--", 3.2), ("#2ca02c", "-", 1.8),
                 ("#d62728", ":", 1.2), ("#9467bd", "-.", 1.0), ("#8c564b", "-", 0.8))
ROW_IN = 1.25  # inches per stream in the timing plot
HEAD_IN = 1.05  # inches above the first row: title, legend, the first row's counts
WIDTH_IN = 11.0
DPI = 100
MAX_BINS = 2000


def short(name: str) -> str:
    return name.removeprefix("EYEQ_").removesuffix("_MSG")


def timing_rows(col: Collected) -> list[Stream]:
    """Streams with a nominal rate, host -> EyeQ first, then by name."""
    rows = [s for s in col.streams.values() if s.period is not None]
    return sorted(rows, key=lambda s: (s.direction != "h2e", s.name))


def timing_figure(col: Collected) -> tuple[Any, dict[str, Any]]:
    """The figure and its axes by message name."""
    rows = timing_rows(col)
    if not rows:
        raise InputError("no periodic messages (DASP or 0x41) in the capture window")
    fig = new_figure(WIDTH_IN, HEAD_IN + 0.45 + ROW_IN * len(rows), DPI)
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    height = fig.get_figheight()
    fig.subplots_adjust(left=0.2, right=0.97, top=1 - HEAD_IN / height,
                        bottom=0.45 / fig.get_figheight(), hspace=0.35)
    end = col.end
    by_name: dict[str, Any] = {}
    for ax, stream in zip(axes, rows, strict=True):
        by_name[stream.name] = ax
        _timing_row(ax, stream, end)
    axes[-1].set_xlabel(TIME_LABEL)
    axes[0].set_xlim(col.window.start, max(end, col.window.start + 1e-3))
    # the title on its own line at the top, the legend's rows below it, the rows below both
    fig.suptitle("inter-arrival time of each message against its nominal period", fontsize=10,
                 y=1 - 0.1 / height, va="top")
    fig.legend(handles=_timing_legend(), loc="upper center", ncol=3, fontsize=7,
               bbox_to_anchor=(0.5, 1 - 0.4 / height), frameon=False)
    return fig, by_name


def _timing_legend() -> list[Any]:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    return [
        Line2D([], [], marker=".", linestyle="", color=DOT_COLOUR, label="inter-arrival time"),
        Line2D([], [], color=BAND_COLOUR, linewidth=1.0, label="nominal period"),
        Patch(facecolor=BAND_COLOUR, alpha=0.25, label="tolerance (§7.1.4)"),
        Patch(facecolor=GAP_COLOUR, alpha=0.35,
              label=f"stopped: silent > {GAP_PERIODS:g} periods"),
        Line2D([], [], marker="^", linestyle="", color=GAP_COLOUR,
               label=f"gap above the axis (> {GAP_PERIODS + 1:g} periods)"),
        Line2D([], [], marker="x", linestyle="", color=GAP_COLOUR, label="DASP counter jump"),
    ]


def rate_label(times: Sequence[float]) -> str:
    """The stream's rate by the one definition (``dissect --stats``, ``monitor``,
    ``conformance``): over its active spans, a gap left out and counted."""
    rate = stream_rate(times)
    hz = "-" if rate.rate_hz is None else f"{rate.rate_hz:.1f}"
    left_out = f" ({plural(len(rate.gaps), 'gap')} left out)" if rate.gaps else ""
    return f"rate {hz} Hz{left_out}"


def _timing_row(ax: Any, stream: Stream, end: float) -> None:
    period = stream.period
    assert period is not None
    p_ms = period * 1e3
    lo, hi = stream.tolerance_ms or (0.0, 0.0)
    top = p_ms * (GAP_PERIODS + 1.0)
    ax.axhspan(p_ms + lo, p_ms + hi, color=BAND_COLOUR, alpha=0.25, linewidth=0, zorder=1)
    ax.axhline(p_ms, color=BAND_COLOUR, linewidth=1.0, zorder=2)
    gaps = stream.gaps(end)
    for gap_start, gap_end in gaps:
        ax.axvspan(gap_start, gap_end, color=GAP_COLOUR, alpha=0.35, linewidth=0, zorder=0)
    times = list(stream.times)
    dts = [(b - a) * 1e3 for a, b in itertools.pairwise(times)]
    xs = times[1:]
    inside = [(x, d) for x, d in zip(xs, dts, strict=True) if d <= top]
    above = [x for x, d in zip(xs, dts, strict=True) if d > top]
    if inside:
        ax.plot([x for x, _ in inside], [d for _, d in inside], ".", markersize=2.5,
                color=DOT_COLOUR, zorder=3)
    if above:
        ax.plot(above, [top * 0.97] * len(above), "^", markersize=4, color=GAP_COLOUR, zorder=3)
    if stream.counter_jumps:
        ax.plot(stream.counter_jumps, [top * 0.85] * len(stream.counter_jumps), "x", markersize=6,
                color=GAP_COLOUR, zorder=4)
    ax.set_ylim(0, top)
    late = sum(1 for d in dts if not p_ms + lo <= d <= p_ms + hi)
    ax.set_ylabel(f"{short(stream.name)}\nms · nominal {stream.rate_hz:g} Hz", fontsize=7)
    ax.tick_params(labelsize=7)
    ax.text(1.0, 1.0, f"{rate_label(times)}, {plural(len(times), 'message')}, {late} outside "
            f"tolerance, {plural(len(gaps), 'silence')}, "
            f"{plural(len(stream.counter_jumps), 'counter jump')}",
            transform=ax.transAxes, fontsize=7,
            ha="right", va="bottom")


def _rebinned(col: Collected) -> tuple[float, dict[int, Counter[str]]]:
    width = col.link_bin
    bins = col.link
    if not bins:
        return width, bins
    factor = max(1, -(-(max(bins) - min(bins) + 1) // MAX_BINS))
    if factor == 1:
        return width, bins
    out: dict[int, Counter[str]] = {}
    for link_bin, counts in bins.items():
        out.setdefault(link_bin // factor, Counter()).update(counts)
    return width * factor, out


def link_figure(col: Collected) -> Any:
    width, bins = _rebinned(col)
    if not bins:
        raise InputError("no timestamped frames in the capture window")
    first, last = min(bins), max(bins)
    xs = [(b + 0.5) * width for b in range(first, last + 1)]
    keys: set[str] = set()
    for counts in bins.values():
        keys.update(counts)

    def series(key: str) -> list[float]:
        return [bins.get(b, Counter()).get(key, 0) / width for b in range(first, last + 1)]

    fig = new_figure(WIDTH_IN, 9.5, DPI)
    axes = fig.subplots(4, 1, sharex=True)
    fig.subplots_adjust(left=0.08, right=0.78, top=0.94, bottom=0.06, hspace=0.25)
    frames = sorted(k for k in keys if k.split(" ")[-1] in ("DATA", "ACK", "NAK", "INVALID"))
    naks = sorted(k for k in keys if k.startswith("NAK 0x"))
    errors = sorted(k for k in keys if k in ("CRC errors", "wrong length", "E2E errors")
                    or k.startswith("abort: "))
    panels = ((axes[0], [k for k in frames if k.startswith("e2h")], "EyeQ \u2192 host\nframes/s"),
              (axes[1], [k for k in frames if not k.startswith("e2h")],
               "host \u2192 EyeQ\nframes/s"),
              (axes[2], naks, "NAKs/s by reason"), (axes[3], errors, "errors/s"))
    for ax, ks, label in panels:
        for name, (colour, style, lw) in zip(ks, itertools.cycle(SERIES_STYLES)):
            ax.plot(xs, series(name), drawstyle="steps-mid", linewidth=lw, label=name,
                    color=colour, linestyle=style, alpha=0.9)
        if not ks:
            ax.text(0.5, 0.5, "none", transform=ax.transAxes, ha="center", va="center",
                    color="#808080")
        else:
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7,
                      title="equal values: nested lines" if len(ks) > 1 else None,
                      title_fontsize=6)
        ax.set_ylabel(label, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_ylim(bottom=0)
        ax.grid(True, color="#e0e0e0", linewidth=0.5)
    axes[-1].set_xlabel(f"{TIME_LABEL}, bins of {width * 1e3:g} ms")
    totals = Counter[str]()
    for counts in bins.values():
        totals.update(counts)
    n_nak = sum(totals[k] for k in naks)
    n_err = sum(totals[k] for k in errors)
    fig.suptitle(f"link: {plural(sum(totals[k] for k in frames), 'frame')}, "
                 f"{plural(n_nak, 'NAK')}, {plural(n_err, 'error')} (CRC, length, aborts, E2E)",
                 fontsize=10)
    return fig
