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
