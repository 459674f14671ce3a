"""PNG figures in the layout of the paper's Figures 10-13, and the plotting convention.

The convention of every figure of the tool: matplotlib's object API on an Agg canvas
(:func:`new_figure`, then ``figure.add_subplot``/``figure.subplots``), written atomically as PNG
(:func:`save_figure`). No ``pyplot`` global state (nothing to close, no figure leaks) and no
global backend switch (``matplotlib.use``), so plotting needs no display and changes nothing
for other users of matplotlib in the same process.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from trainer.data.channels import Signal
from trainer.errors import atomic_output

MAX_PLOT_POINTS = 20_000


def new_figure(figsize: tuple[float, float], dpi: float) -> Figure:
    """An empty figure of ``figsize`` inches at ``dpi``, on its own Agg canvas."""
    figure = Figure(figsize=figsize, dpi=dpi)
    FigureCanvasAgg(figure)
    return figure


def save_figure(figure: Figure, path: str | os.PathLike[str]) -> Path:
    """Write ``figure`` to ``path`` as PNG atomically (no partial file on failure); returns the path."""
    target = Path(path)
    with atomic_output(target) as tmp:
        figure.savefig(tmp, format="png")
    return target


def _thin(n: int) -> slice:
    """A stride that keeps at most MAX_PLOT_POINTS points: a 1.44 M-point line is unreadable anyway."""
    return slice(None, None, max(1, n // MAX_PLOT_POINTS))


def plot_series(
    time_s: np.ndarray,
    series: dict[str, np.ndarray],
    path: str | os.PathLike[str],
    *,
    title: str,
    signal: Signal,
) -> None:
    """Several signals against time on one axis (Figures 10-12: fitted or compensated outputs), the
    axis and title naming ``signal``'s channel and unit."""
    step = _thin(len(time_s))
    fig = new_figure((10, 5), 110)
    ax = fig.add_subplot()
    for label, values in series.items():
        ax.plot(time_s[step] / 60.0, values[step], label=label, linewidth=0.8)
    ax.set_xlabel("time (min)")
    ax.set_ylabel(signal.axis())
    ax.set_title(signal.title(title))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


def plot_fit(
    time_s: np.ndarray,
    reference_label: str,
    reference: np.ndarray,
    estimates: dict[str, np.ndarray],
    path: str | os.PathLike[str],
    *,
    title: str,
    signal: Signal,
) -> None:
    """Figures 10-11: estimates over the reference (top) and their differences from it (bottom).

    At the scale of the drift every good fit looks the same; the lower panel shows where they differ.
    """
    step = _thin(len(time_s))
    minutes = time_s[step] / 60.0
    fig = new_figure((10, 7), 110)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    top.plot(minutes, reference[step], label=reference_label, color="black", linewidth=1.2)
    for label, values in estimates.items():
        top.plot(minutes, values[step], label=label, linewidth=0.8)
        bottom.plot(minutes, (values - reference)[step], label=label, linewidth=0.7)
    top.set_ylabel(signal.axis())
    top.set_title(signal.title(title))
    top.legend(loc="best", fontsize=8)
    bottom.set_ylabel(signal.axis("estimate - reference"))
    bottom.set_xlabel("time (min)")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)
