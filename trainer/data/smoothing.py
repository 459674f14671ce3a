"""Smoothing and decimation shared by the trainer and the generated firmware C.

The firmware reproduces these functions sample by sample, so each one is defined exactly
(0-based indices, ``x`` has ``n`` samples):

* :func:`window_samples`: ``max(1, floor(window_s * rate_hz + 0.5))``, i.e. round half up (the C
  code uses the same expression; Python's ``round`` would round half to even).
* :func:`moving_average`, ``mode="trailing"`` (causal, what the firmware runs)::

      m_i  = min(window, i + 1)
      y[i] = (x[i - m_i + 1] + ... + x[i]) / m_i

  The window expands over the first ``window - 1`` samples (mean of what has arrived so far),
  so there is no start-up transient towards zero.
* :func:`moving_average`, ``mode="centered"`` (offline only, like MATLAB ``smooth``)::

      h    = (window - 1) // 2          # an even window behaves like window - 1
      k_i  = min(h, i, n - 1 - i)       # the window shrinks symmetrically at both ends
      y[i] = (x[i - k_i] + ... + x[i + k_i]) / (2 * k_i + 1)

* :func:`decimate`: keeps ``x[factor - 1], x[2 * factor - 1], ...``, the last sample of each
  complete block of ``factor`` samples, so a streaming implementation emits an output exactly
  when a block completes; an incomplete final block is dropped. ``decimate(moving_average(x, f),
  f)`` is therefore the mean of each complete block of ``f`` samples.

Inputs are expected finite (recordings are validated on reading); a nan spreads to every later
output of the cumulative sums.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

SmoothingMode = Literal["trailing", "centered"]


def window_samples(window_s: float, rate_hz: float) -> int:
    """Length in samples of a window given in seconds: nearest integer (half up), at least 1."""
    if not (math.isfinite(window_s) and window_s >= 0):
        raise ValueError(f"window_s must be a finite number >= 0, got {window_s!r}")
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a finite number > 0, got {rate_hz!r}")
    return max(1, math.floor(window_s * rate_hz + 0.5))


def _check_factor(value: int, what: str) -> int:
    if isinstance(value, bool) or int(value) != value or value < 1:
        raise ValueError(f"{what} must be an integer >= 1, got {value!r}")
    return int(value)


def moving_average(x: ArrayLike, window: int, mode: SmoothingMode = "trailing") -> np.ndarray:
    """Moving mean of a 1-D signal as defined in the module docstring; returns float64.

    Uses one cumulative sum (O(n) whatever the window). The first sample is subtracted before
    summing so the running sum stays small (a -1 g axis keeps its mg digits over 1.44 M samples);
    using the first sample, not the mean, keeps trailing outputs independent of later samples.
    """
    window = _check_factor(window, "window")
    values = np.asarray(x, dtype=np.float64)
    if values.ndim != 1:
        raise ValueError(f"moving_average expects a 1-D signal, got shape {values.shape}")
    n = values.size
    if n == 0:
        return values.copy()
    offset = float(values[0])
    sums = np.concatenate(([0.0], np.cumsum(values - offset)))  # sums[j] = sum of x[:j]
    index = np.arange(n)
    if mode == "trailing":
        start = np.maximum(index - window + 1, 0)
        stop = index + 1
    elif mode == "centered":
        half = np.minimum(np.minimum((window - 1) // 2, index), n - 1 - index)
        start = index - half
        stop = index + half + 1
    else:
        raise ValueError(f"mode must be 'trailing' or 'centered', got {mode!r}")
    return offset + (sums[stop] - sums[start]) / (stop - start)


def decimation_indices(n: int, factor: int) -> np.ndarray:
    """Indices ``factor - 1, 2 * factor - 1, ...`` below ``n``: the samples :func:`decimate` keeps."""
    factor = _check_factor(factor, "factor")
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n!r}")
    return np.arange(factor - 1, n, factor)


def decimate(x: ArrayLike, factor: int) -> np.ndarray:
    """The last sample of each complete block of ``factor`` samples (along the first axis; a view).

    No anti-alias filter: smooth first with :func:`moving_average` when that matters.
    """
    factor = _check_factor(factor, "factor")
    values = np.asarray(x)
    if values.ndim == 0:
        raise ValueError("decimate expects an array, got a scalar")
    return values[factor - 1 :: factor]
