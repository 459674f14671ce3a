"""The flight-stack baseline: a cubic of the drift in temperature about a reference temperature.

This follows PX4's ``Tools/process_sensor_caldata.py`` for accelerometers, which is what many
GNC teams run today (ArduPilot's ``tcal`` is the same idea):

1. median-filter the axis over 31 samples;
2. ``T_ref = (T_min + T_max) / 2`` of the logged temperature, ``dT = T - T_ref``;
3. average the samples into 2000 equal-width temperature bins (so a slow part of the ramp does
   not dominate the fit), then ``numpy.polyfit(dT, drift, 3)``;
4. when applied, the temperature is clipped to ``[T_min, T_max]`` (the valid range) first.

One deliberate difference, controlled by ``remove_median``: PX4 subtracts the axis median before
fitting because its separate six-position calibration owns the constant offset. The paper's
static test defines the drift with a zero reference, so by default the constant term is fitted
too (``remove_median=False``) and the cubic is compared like-for-like with PLA and the DLSTM.
The tool's offset policy (:mod:`trainer.reference`, relative to ``T_ref`` by default) then moves
the fitted constant out of the model, which is what PX4's median removal is for.
"""

from __future__ import annotations

from typing import Any, Self

import numpy as np
import torch
from scipy.ndimage import median_filter

from trainer import payload as payload_fields
from trainer.baselines.base import TemperatureCompensator
from trainer.errors import UserError
from trainer.reference import reference_temperature

PX4_MEDIAN_KERNEL = 31
PX4_TEMPERATURE_BINS = 2000
# A lower order (a line, a parabola; 0: no compensation at all) is what `--method auto` tries where
# the cubic over-fits a short range; the model keeps four coefficients, so the C and the flight-stack
# parameters are those of the cubic with the higher ones zero.
DEGREES = (0, 1, 2, 3)


def bin_by_temperature(temp: np.ndarray, values: np.ndarray, n_bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean temperature and mean value of each non-empty equal-width temperature bin."""
    t_min, t_max = float(np.min(temp)), float(np.max(temp))
    width = (t_max - t_min) / n_bins
    index = np.clip(((temp - t_min) / width).astype(np.int64), 0, n_bins - 1)
    counts = np.bincount(index, minlength=n_bins)
    sum_t = np.bincount(index, weights=temp, minlength=n_bins)
    sum_v = np.bincount(index, weights=values, minlength=n_bins)
    keep = counts > 0
    return sum_t[keep] / counts[keep], sum_v[keep] / counts[keep]


def shift_polynomial(coefficients: np.ndarray, from_ref: float, to_ref: float) -> np.ndarray:
    """Coefficients of the same polynomial in ``T - to_ref`` (exact algebra: a binomial re-expansion)."""
    poly = np.polynomial.Polynomial(coefficients)
    shifted = poly(np.polynomial.Polynomial([to_ref - from_ref, 1.0])).coef
    return np.pad(shifted, (0, len(coefficients) - len(shifted)))


class CubicPolynomial(TemperatureCompensator):
    """PX4-style per-axis cubic thermal calibration (offset only)."""

    def __init__(
        self,
        *,
        remove_median: bool = False,
        median_kernel: int = PX4_MEDIAN_KERNEL,
        n_bins: int = PX4_TEMPERATURE_BINS,
        degree: int = 3,
    ) -> None:
        if degree not in DEGREES:
            raise UserError(f"poly3: degree {degree} is not one of {DEGREES}")
        self.degree = degree
        self.remove_median = remove_median
        self.median_kernel = median_kernel
        self.n_bins = n_bins
        self.coefficients = np.zeros(4)  # c0..c3 of dT^0..dT^3, in mg / degC^k
        self.t_ref_c = 0.0
        self.temp_range_c = (np.nan, np.nan)

    def fit_arrays(self, temp_c: np.ndarray, drift_mg: np.ndarray) -> Self:
        t_min, t_max = float(np.min(temp_c)), float(np.max(temp_c))
        if not t_max > t_min:
            raise UserError(f"poly3: the training temperature does not vary (constant {t_min} degC)")
        drift = (
            median_filter(drift_mg, size=self.median_kernel, mode="nearest")
            if self.median_kernel > 1
            else drift_mg
        )
        if self.remove_median:
            drift = drift - np.median(drift)
        self.t_ref_c = reference_temperature(temp_c)
        temp_rel = temp_c - self.t_ref_c
        if self.n_bins > 0:
            temp_rel, drift = bin_by_temperature(temp_rel, drift, self.n_bins)
        if np.unique(temp_rel).size < 4:
            binned = (
                f" after averaging into {self.n_bins} bins over {t_min:g} .. {t_max:g} degC"
                if self.n_bins > 0 and np.unique(temp_c).size >= 4
                else ""
            )
            hint = " (a few outlying temperatures stretch the range?)" if binned else ""
            raise UserError(
                f"poly3: fewer than 4 distinct temperatures{binned}; a cubic is not determined{hint}"
            )
        self.coefficients = np.zeros(4)
        if self.degree > 0:
            self.coefficients[: self.degree + 1] = np.polynomial.polynomial.polyfit(
                temp_rel, drift, self.degree
            )
        self.temp_range_c = (t_min, t_max)
        return self

    def drift_at(self, temp_c: np.ndarray) -> np.ndarray:
        clipped = np.clip(temp_c, *self.temp_range_c)
        return np.polynomial.polynomial.polyval(clipped - self.t_ref_c, self.coefficients)

    def expand_about(self, t_ref_c: float) -> None:
        if t_ref_c != self.t_ref_c:
            self.coefficients = shift_polynomial(self.coefficients, self.t_ref_c, t_ref_c)
            self.t_ref_c = t_ref_c

    def shift_drift(self, delta_mg: float) -> None:
        self.coefficients = self.coefficients + np.array([delta_mg, 0.0, 0.0, 0.0])

    def to_payload(self) -> dict[str, Any]:
        return {
            "coefficients_mg": torch.from_numpy(self.coefficients.copy()),
            "t_ref_c": float(self.t_ref_c),
            "temp_range_c": [float(v) for v in self.temp_range_c],
            "remove_median": bool(self.remove_median),
            "median_kernel": int(self.median_kernel),
            "n_bins": int(self.n_bins),
            "degree": int(self.degree),
        }

    @classmethod
    def from_payload(cls, payload: dict[str, Any]) -> Self:
        model = cls(
            remove_median=payload_fields.flag(payload, "remove_median"),
            median_kernel=payload_fields.count(payload, "median_kernel", 1),
            n_bins=payload_fields.count(payload, "n_bins", 1),
            degree=payload_fields.count(payload, "degree", 0, 3) if "degree" in payload else 3,
        )
        model.coefficients = payload_fields.table(payload, "coefficients_mg", 4)
        if np.any(model.coefficients[model.degree + 1 :] != 0.0):
            raise ValueError(
                f"payload.degree is {model.degree}, but coefficients_mg has a non-zero term of a higher order"
            )
        model.t_ref_c = payload_fields.number(payload["t_ref_c"], "payload.t_ref_c")
        model.temp_range_c = payload_fields.temp_range(payload)
        return model
