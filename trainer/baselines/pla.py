"""Piecewise linear approximation (PLA), section 3.2 of Guo et al. 2023.

The training temperature range ``[T_min, T_max]`` is cut into ``n_intervals`` (10) intervals of
equal width; in each one an ordinary least-squares line ``U = k T + b`` is fitted to the samples
whose temperature falls into it. The 9 inner boundaries are the split points.

Applying the model: a temperature selects its interval by the split points, exactly as the paper
describes, so the segments are *not* forced to join. Outside the trained range the first and last
intervals' lines continue (linear extrapolation): below the first split point is interval 0, at or
above the last split point is the last interval. ``out_of_range(T)`` tells the caller when that
happens, and the checkpoint records the valid range, so firmware can flag it.

An interval holding fewer than two distinct temperatures cannot define a line; it gets a
constant (the mean drift of its samples, or of its nearest populated neighbour when empty).
"""

from __future__ import annotations

from typing import Any, Self

import numpy as np
import torch

from trainer import payload as payload_fields
from trainer.baselines.base import TemperatureCompensator
from trainer.budget import FLOAT_BYTES, check_memory, check_time
from trainer.errors import UserError

TABLES = 4  # float64 tables of one entry per interval while fitting (edges, slopes, intercepts, splits)
# Fitting masks every row once per interval: 5.7 ns per interval and row (1000 intervals on
# 1.44 M rows took 8.2 s), the time budget's estimate.
SECONDS_PER_INTERVAL_ROW = 5e-9
_FEWER = "use fewer --intervals (the paper uses 10)"


def check_intervals(n_intervals: int) -> int:
    """``n_intervals`` if it is >= 1 and its tables fit the memory budget (one line otherwise)."""
    if n_intervals < 1:
        raise UserError(f"pla: --intervals must be >= 1, got {n_intervals}")
    check_memory(float(n_intervals) * TABLES * FLOAT_BYTES, f"pla: --intervals {n_intervals}", _FEWER)
    return n_intervals


class PiecewiseLinear(TemperatureCompensator):
    """The paper's PLA baseline: temperature in, drift out, one line per temperature interval."""

    def __init__(self, n_intervals: int = 10) -> None:
        self.n_intervals = check_intervals(n_intervals)
        self.split_points_c = np.empty(0)
        self.slopes_mg_per_c = np.empty(0)
        self.intercepts_mg = np.empty(0)
        self.temp_range_c = (np.nan, np.nan)

    def fit_arrays(self, temp_c: np.ndarray, drift_mg: np.ndarray) -> Self:
        """Fit from plain arrays (temperature, drift); used by :meth:`fit` and the tests."""
        if self.n_intervals > temp_c.size // 2:
            raise UserError(
                f"pla: --intervals {self.n_intervals} is more than half the {temp_c.size} training rows: "
                f"an interval needs two samples for a line; {_FEWER}"
            )
        check_time(
            float(self.n_intervals) * temp_c.size * SECONDS_PER_INTERVAL_ROW,
            f"pla: --intervals {self.n_intervals} on {temp_c.size} rows",
            _FEWER,
        )
        t_min, t_max = float(np.min(temp_c)), float(np.max(temp_c))
        if not t_max > t_min:
            raise UserError(f"pla: the training temperature does not vary (constant {t_min} degC)")
        edges = np.linspace(t_min, t_max, self.n_intervals + 1)
        self.split_points_c = edges[1:-1].copy()
        index = self.interval_index(temp_c)
        slopes = np.full(self.n_intervals, np.nan)
        intercepts = np.full(self.n_intervals, np.nan)
        for k in range(self.n_intervals):
            t_k, u_k = temp_c[index == k], drift_mg[index == k]
            if t_k.size >= 2 and np.ptp(t_k) > 0:
                slopes[k], intercepts[k] = np.polynomial.polynomial.polyfit(t_k, u_k, 1)[::-1]
            elif t_k.size:
                slopes[k], intercepts[k] = 0.0, float(np.mean(u_k))
        _fill_empty_from_neighbours(slopes, intercepts)
        self.slopes_mg_per_c, self.intercepts_mg = slopes, intercepts
        self.temp_range_c = (t_min, t_max)
        return self

    def interval_index(self, temp_c: np.ndarray) -> np.ndarray:
        """Interval of each temperature by the split points (ends are open: extrapolation)."""
        return np.searchsorted(self.split_points_c, temp_c, side="right")

    def drift_at(self, temp_c: np.ndarray) -> np.ndarray:
        index = self.interval_index(temp_c)
        return self.slopes_mg_per_c[index] * temp_c + self.intercepts_mg[index]

    def shift_drift(self, delta_mg: float) -> None:
        self.intercepts_mg = self.intercepts_mg + delta_mg

    def to_payload(self) -> dict[str, Any]:
        return {
            "n_intervals": self.n_intervals,
            "split_points_c": torch.from_numpy(self.split_points_c.copy()),
            "slopes_mg_per_c": torch.from_numpy(self.slopes_mg_per_c.copy()),
            "intercepts_mg": torch.from_numpy(self.intercepts_mg.copy()),
            "temp_range_c": [float(v) for v in self.temp_range_c],
        }

    @classmethod
    def from_payload(cls, payload: dict[str, Any]) -> Self:
        model = cls(payload_fields.count(payload, "n_intervals", 1))
        model.split_points_c = payload_fields.table(payload, "split_points_c", model.n_intervals - 1)
        if np.any(np.diff(model.split_points_c) < 0):  # the interval lookup (here and in C) needs them sorted
            raise ValueError("payload.split_points_c must be in ascending order")
        model.slopes_mg_per_c = payload_fields.table(payload, "slopes_mg_per_c", model.n_intervals)
        model.intercepts_mg = payload_fields.table(payload, "intercepts_mg", model.n_intervals)
        model.temp_range_c = payload_fields.temp_range(payload)
        return model


def _fill_empty_from_neighbours(slopes: np.ndarray, intercepts: np.ndarray) -> None:
    """Give intervals without samples the line of the nearest populated interval (in place)."""
    populated = np.flatnonzero(~np.isnan(slopes))
    for k in np.flatnonzero(np.isnan(slopes)):
        nearest = populated[np.argmin(np.abs(populated - k))]
        slopes[k], intercepts[k] = slopes[nearest], intercepts[nearest]
