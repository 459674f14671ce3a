"""Thermal building blocks: the exact first-order low-pass and the play (backlash) operator.

Both are written for long uniformly sampled arrays (1.44 million samples and more) without a
per-sample Python loop: the low-pass is one ``scipy.signal.lfilter`` call, the play operator a
handful of numpy running-max/min scans, one per reversal of the input.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter


def lowpass_coefficients(tau_s: float, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(b, a)`` of ``dy/dt = (x - y) / tau`` discretised exactly for ``x`` linear between samples.

    First-order-hold ("ramp-invariant") discretisation: with ``a = exp(-dt/tau)`` and
    ``x`` interpolated linearly from ``x[n-1]`` to ``x[n]``, the continuous solution at the
    sample instants is ``y[n] = a y[n-1] + b0 x[n] + b1 x[n-1]`` with
    ``b0 = 1 - (tau/dt)(1 - a)`` and ``b1 = (tau/dt)(1 - a) - a``. A linear ramp (the oven's
    set-point) is therefore filtered with no discretisation error at all, unlike zero-order hold,
    which would add a lag of half a sample. ``b0 + b1 = 1 - a`` exactly, so the DC gain is 1.
    """
    if not (tau_s > 0 and dt_s > 0):
        raise ValueError(f"lowpass needs tau_s > 0 and dt_s > 0, got {tau_s}, {dt_s}")
    x = dt_s / tau_s
    a = math.exp(-x)
    one_minus_a = 1.0 - a  # exact in floating point (Sterbenz), so b0 + b1 == 1 - a: DC gain 1
    # b0 = 1 - (1 - a)/x; for tau >> dt its series avoids the cancellation
    b0 = x / 2 - x**2 / 6 + x**3 / 24 - x**4 / 120 if x < 1e-3 else 1.0 - one_minus_a / x
    b1 = one_minus_a - b0
    return np.array([b0, b1]), np.array([1.0, -a])


def lowpass(x: np.ndarray, tau_s: float, dt_s: float) -> np.ndarray:
    """``LP(x, tau)`` sampled every ``dt_s``, started in equilibrium ``y[0] = x[0]`` (catalogue)."""
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return x.copy()
    b, a = lowpass_coefficients(tau_s, dt_s)
    # Filter the deviation from x[0] from a zero state: equilibrium start y[0] = x[0], and the
    # rounding of a pole near 1 acts on small deviations instead of on the absolute temperature.
    x0 = x[0]
    return x0 + lfilter(b, a, x - x0)


def play_operator(x: np.ndarray, width: float, initial: float | None = None) -> np.ndarray:
    """Play operator ``P[n] = min(max(P[n-1], x[n] - w/2), x[n] + w/2)``, ``P[0]`` from ``initial``.

    ``initial`` defaults to ``x[0]`` (catalogue: started at ``P_0 = T_0``). The output alternates
    between an "up" phase (``P`` is the running maximum of ``x - w/2``) and a "down" phase (the
    running minimum of ``x + w/2``); each phase is one numpy scan over a growing window, so the
    cost is O(N) plus a small constant per reversal of the input.
    """
    x = np.asarray(x, dtype=np.float64)
    if not width >= 0:
        raise ValueError(f"play operator width must be >= 0, got {width}")
    n = x.size
    out = np.empty(n)
    if n == 0:
        return out
    half = width / 2.0
    lo = x - half
    hi = x + half
    p = float(x[0]) if initial is None else float(initial)
    p = min(max(p, lo[0]), hi[0])
    out[0] = p
    i = 1
    going_up = True
    window = 256
    phases = 0
    while i < n:
        if phases > 1000 and i < 256 * phases:
            # Input reverses every few samples (noise wider than w): scans no longer pay off.
            _play_loop(lo, hi, out, i)
            break
        j = min(n, i + window)
        if going_up:  # P = max(P_prev, lo) until the upper clip x + w/2 binds
            run = np.maximum(p, np.maximum.accumulate(lo[i:j]))
            broken = np.flatnonzero(run > hi[i:j])
        else:  # P = min(P_prev, hi) until the lower clip x - w/2 binds
            run = np.minimum(p, np.minimum.accumulate(hi[i:j]))
            broken = np.flatnonzero(run < lo[i:j])
        if broken.size == 0:
            out[i:j] = run
            p = float(run[-1])
            i = j
            window = min(window * 4, 1 << 20)
            continue
        k = int(broken[0])
        out[i : i + k] = run[:k]
        p = float(hi[i + k] if going_up else lo[i + k])
        out[i + k] = p
        i += k + 1
        going_up = not going_up
        phases += 1
        window = max(256, 2 * k)
    return out


def _play_loop(lo: np.ndarray, hi: np.ndarray, out: np.ndarray, start: int) -> None:
    """Plain recursion from ``start`` on (``out[start-1]`` is the previous output)."""
    p = float(out[start - 1])
    lo_list = lo[start:].tolist()
    hi_list = hi[start:].tolist()
    tail = [0.0] * len(lo_list)
    for idx, (low, high) in enumerate(zip(lo_list, hi_list, strict=True)):
        p = min(max(p, low), high)
        tail[idx] = p
    out[start:] = tail
