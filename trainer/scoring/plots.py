"""PNG figures in the layout of the paper's Figures 10-13 (matplotlib, Agg backend)."""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from trainer.errors import atomic_output

MAX_PLOT_POINTS = 20_000


def _thin(n: int) -> slice:
    """A stride that keeps at most MAX_PLOT_POINTS points: a 1.44 M-point line is unreadable anyway."""
    return slice(None, None, max(1, n // MAX_PLOT_POINTS))


def plot_series(
    time_s: np.ndarray,
    series: dict[str, np.ndarray],
    path: str | os.PathLike[str],
    *,
    title: str,
    ylabel: str = "acceleration (mg)",
) -> None:
    """Several signals against time on one axis (Figures 10-12: fitted or compensated outputs)."""
    step = _thin(len(time_s))
    fig, ax = plt.subplots(figsize=(10, 5), dpi=110)
    for label, values in series.items():
        ax.plot(time_s[step] / 60.0, values[step], label=label, linewidth=0.8)
    ax.set_xlabel("time (min)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def plot_fit(
    time_s: np.ndarray,
    reference_label: str,
    reference: np.ndarray,
    estimates: dict[str, np.ndarray],
    path: str | os.PathLike[str],
    *,
    title: str,
) -> None:
    """Figures 10-11: estimates over the reference (top) and their differences from it (bottom).

    At the scale of the drift every good fit looks the same; the lower panel shows where they differ.
    """
    step = _thin(len(time_s))
    minutes = time_s[step] / 60.0
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 7), dpi=110, sharex=True, height_ratios=(3, 2))
    top.plot(minutes, reference[step], label=reference_label, color="black", linewidth=1.2)
    for label, values in estimates.items():
        top.plot(minutes, values[step], label=label, linewidth=0.8)
        bottom.plot(minutes, (values - reference)[step], label=label, linewidth=0.7)
    top.set_ylabel("acceleration (mg)")
    top.set_title(title)
    top.legend(loc="best", fontsize=8)
    bottom.set_ylabel("estimate - reference (mg)")
    bottom.set_xlabel("time (min)")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
