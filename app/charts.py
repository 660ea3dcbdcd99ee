"""Charts shared by bench, sweep and studies: one style, matplotlib's Agg backend (no display
needed), PNGs written atomically.

    from app import charts
    fig, ax = charts.figure("error against time", "ms per step", "L1 error", log=("x", "y"))
    charts.series(ax, xs, ys, label="fp32", notes=["64", "128"])
    charts.save(fig, "out/study.png", source="PoCL, 2026-12-01")

matplotlib is imported on first use, never at import time of this module.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

#: One palette for every chart (colour-blind friendly, Okabe-Ito).
PALETTE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442",
           "#000000")
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


def _plt():
    import matplotlib

    if matplotlib.get_backend().lower() != "agg":
        matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    plt.rcParams.update({
        "figure.dpi": 110, "savefig.dpi": 120, "font.size": 9, "axes.titlesize": 10,
        "axes.grid": True, "grid.alpha": 0.3, "axes.axisbelow": True, "axes.spines.top": False,
        "axes.spines.right": False, "legend.fontsize": 8, "legend.frameon": False,
        "axes.prop_cycle": matplotlib.cycler(color=PALETTE),
    })
    return plt


def figure(title: str, xlabel: str, ylabel: str, *, log: Sequence[str] = (),
           size: tuple[float, float] = (6.4, 4.0)):
    """A new (figure, axes) in the house style; ``log`` names the logarithmic axes ("x", "y")."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=size)
    ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    for name in log:
        (ax.set_xscale if name == "x" else ax.set_yscale)("log")
    return fig, ax


def panels(title: str, n: int, *, size: tuple[float, float] = (6.4, 4.0)):
    """A figure of ``n`` side-by-side axes in the house style under one title: (fig, [axes])."""
    plt = _plt()
    fig, axes = plt.subplots(1, n, figsize=size, squeeze=False)
    fig.suptitle(title, fontsize=9)
    return fig, list(axes[0])


def marker_handle(colour, marker: str, label: str):
    """A legend entry for scattered markers (for ``fig.legend(handles=...)``)."""
    from matplotlib.lines import Line2D

    return Line2D([], [], linestyle="none", marker=marker, color=colour, markersize=7,
                  label=label)


def series(ax, xs, ys, *, label: str | None = None, notes: Sequence[str] | None = None,
           index: int | None = None, line: bool = True):
    """One series of points (and a line through them), each point optionally annotated."""
    i = len(ax.get_lines()) if index is None else index
    ax.plot(list(xs), list(ys), marker=MARKERS[i % len(MARKERS)],
            linestyle="-" if line else "none", color=PALETTE[i % len(PALETTE)], label=label,
            markersize=5, linewidth=1.3)
    for x, y, note in zip(xs, ys, notes or (), strict=False):
        ax.annotate(str(note), (x, y), fontsize=7, xytext=(4, 3), textcoords="offset points")


def reference(ax, xs, ys, *, label: str, notes: Sequence[str] | None = None):
    """Reference points (for example the seed's published numbers): grey, hollow, no line."""
    ax.plot(list(xs), list(ys), marker="o", markerfacecolor="none", linestyle=":",
            color="0.45", label=label, markersize=7)
    for x, y, note in zip(xs, ys, notes or (), strict=False):
        ax.annotate(str(note), (x, y), fontsize=7, color="0.35", xytext=(4, -9),
                    textcoords="offset points")


def stacked_bars(ax, categories: Sequence[str], stacks: dict[str, Sequence[float]]):
    """Bars per category, one stacked segment per key of ``stacks`` (values per category)."""
    import numpy as np

    bottom = np.zeros(len(categories))
    xs = np.arange(len(categories))
    for i, (name, vals) in enumerate(stacks.items()):
        v = np.asarray(vals, dtype=float)
        ax.bar(xs, v, bottom=bottom, label=name, color=PALETTE[i % len(PALETTE)], width=0.6)
        bottom += v
    ax.set_xticks(xs, list(categories))
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))


def _plain_log_labels(ax) -> None:
    """Log axes labelled 20, 300, 0.01 rather than 2x10^1; minor ticks labelled (2 and 5 of each
    decade) only when the axis spans at most two decades, so labels never crowd."""
    import math

    from matplotlib.ticker import FuncFormatter, NullFormatter

    for axis, lim in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
        if axis.get_scale() != "log" or min(lim) <= 0:
            continue
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        if math.log10(max(lim) / min(lim)) > 2:
            axis.set_minor_formatter(NullFormatter())
            continue

        def minor(v, _):
            m = v / 10 ** math.floor(math.log10(v) + 1e-9)
            return f"{v:g}" if round(m, 6) in (2.0, 5.0) else ""
        axis.set_minor_formatter(FuncFormatter(minor))
        axis.set_tick_params(which="minor", labelsize=7)


def save(fig, path: str | os.PathLike, *, source: str | None = None,
         bottom: float = 0.02) -> None:
    """Write ``fig`` as a PNG atomically (temporary file, then rename) and close it. ``source``
    is a small footnote (device, date, mode) so a chart never travels without its provenance;
    ``bottom``: the figure fraction kept free below the axes (a figure legend)."""
    from app.io import atomic_path

    plt = _plt()
    ax = fig.axes[0] if fig.axes else None
    if ax is not None and ax.get_legend() is None and ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best")
    if source:
        fig.text(0.99, 0.005, source, ha="right", va="bottom", fontsize=6, color="0.4")
    for a in fig.axes:
        _plain_log_labels(a)
    fig.tight_layout(rect=(0, bottom, 1, 1))
    try:
        with atomic_path(path, suffix=".partial.png") as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
