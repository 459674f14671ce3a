"""Drift left without ground truth: a static recording's compensated output against a constant.

On a static fixture (the chamber runs this tool is made for) the true input is constant, so
whatever a compensated output does besides sensor noise is drift the compensator left:

- the **drift left** is ``x - mean(x)`` of the compensated output ``x`` (after the same validation
  smoothing as the Allan analysis): its RMS and its maximum magnitude over the whole recording,
  and its RMS over the heating and over the cooling samples, all about the *one* overall
  constant, so a heating/cooling difference (hysteresis, lag) counts as drift left;
- the **branch** of a sample comes from the sign of the temperature rate: a centred least-squares
  slope over :data:`RATE_WINDOW_S` (Savitzky-Golay derivative), heating above
  +:data:`DEAD_BAND_C_PER_MIN`, cooling below its negative, neither in between (dwells, turning
  points);
- the **noise floor** is what no compensator can remove: the white-noise RMS of the raw output from
  its first differences (``1.4826 MAD(diff(x)) / sqrt(2)``: the median absolute deviation, so that
  the few large differences of a step or a ramp's turn do not count as noise; the standard
  deviation when the MAD is zero, e.g. coarse quantisation), divided by ``sqrt(N)`` for the
  ``N``-sample moving average the scores are computed after. A drift left near the floor is all
  noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter

RATE_WINDOW_S = 60.0
DEAD_BAND_C_PER_MIN = 0.2
HEATING, COOLING, NEITHER = 1, -1, 0
MAD_TO_SIGMA = 1.4826  # median absolute deviation -> standard deviation of a normal distribution


def temperature_rate_c_per_min(
    temp_c: np.ndarray, rate_hz: float, window_s: float = RATE_WINDOW_S
) -> np.ndarray:
    """Centred least-squares slope of the temperature over ``window_s``, in degC/min."""
    n = len(temp_c)
    window = min(max(3, round(window_s * rate_hz) | 1), n if n % 2 else n - 1)
    if window < 3:
        return np.zeros(n)
    slope = savgol_filter(np.asarray(temp_c, dtype=np.float64), window, 1, deriv=1, delta=1.0 / rate_hz)
    return 60.0 * slope


def thermal_branch(
    temp_c: np.ndarray,
    rate_hz: float,
    dead_band_c_per_min: float = DEAD_BAND_C_PER_MIN,
    window_s: float = RATE_WINDOW_S,
) -> np.ndarray:
    """:data:`HEATING`, :data:`COOLING` or :data:`NEITHER` for every sample."""
    rate = temperature_rate_c_per_min(temp_c, rate_hz, window_s)
    branch = np.full(len(rate), NEITHER, dtype=np.int8)
    branch[rate > dead_band_c_per_min] = HEATING
    branch[rate < -dead_band_c_per_min] = COOLING
    return branch


@dataclass(frozen=True)
class DriftLeft:
    """RMS and maximum of a drift-left series, overall and per branch (NaN: no such samples).

    The ``_mg`` fields are in the scored channel's unit (mg for an accelerometer's ``accel_mg``,
    deg/s or Pa for a one-channel view of a gyroscope or barometer, :mod:`trainer.data.channels`).
    """

    rms_mg: float
    max_abs_mg: float
    heating_rms_mg: float
    cooling_rms_mg: float
    samples: int = 0
    heating_samples: int = 0
    cooling_samples: int = 0
    heating_max_abs_mg: float = math.nan
    cooling_max_abs_mg: float = math.nan


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else math.nan


def _max_abs(x: np.ndarray) -> float:
    return float(np.max(np.abs(x))) if x.size else math.nan


def summarise(residual: np.ndarray, branch: np.ndarray) -> DriftLeft:
    """The scores of a drift-left series (already about its reference)."""
    heating, cooling = residual[branch == HEATING], residual[branch == COOLING]
    return DriftLeft(
        _rms(residual),
        _max_abs(residual),
        _rms(heating),
        _rms(cooling),
        int(residual.size),
        int(heating.size),
        int(cooling.size),
        _max_abs(heating),
        _max_abs(cooling),
    )


def static_drift_left(compensated: np.ndarray, branch: np.ndarray) -> DriftLeft:
    """Deviation of a static recording's compensated output from one constant (its mean)."""
    x = np.asarray(compensated, dtype=np.float64)
    return summarise(x - x.mean(), branch)


def noise_floor_mg(raw: np.ndarray, smoothing_samples: int = 1) -> float:
    """White-noise RMS of ``raw`` from first differences, after an N-sample moving average."""
    if len(raw) < 3:
        return math.nan
    diff = np.diff(np.asarray(raw, dtype=np.float64))
    spread = MAD_TO_SIGMA * float(np.median(np.abs(diff - np.median(diff))))
    white = (spread if spread > 0 else float(np.std(diff))) / math.sqrt(2.0)
    return white / math.sqrt(max(1, smoothing_samples))
