"""Integer rounding and saturation shared by the quantiser and the golden model.

One rounding rule everywhere: **round half away from zero**, offline (quantising a constant) and
at run time (a rounding right shift, a rounding division). It is symmetric, so ``f(-x) = -f(x)``
holds for every odd function of the generated code (tanh, the linear layers), and in C it is
written on unsigned magnitudes, which avoids the implementation-defined right shift of a negative
value. The numpy versions here work on int64 arrays; every caller keeps its operands inside the
ranges proved at generation time, so int64 never wraps (a wrap would be a bug, not a rounding).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

INT16_MAX = (1 << 15) - 1
INT32_MAX = (1 << 31) - 1
INT32_MIN = -(1 << 31)
INT64_MAX = (1 << 63) - 1


def round_half_away(value: Fraction | int) -> int:
    """Nearest integer of an exact rational, ties away from zero."""
    value = Fraction(value)
    magnitude = math.floor(abs(value) + Fraction(1, 2))
    return -magnitude if value < 0 else magnitude


def quantise(value: float, frac_bits: int) -> int:
    """``round(value * 2**frac_bits)`` computed exactly from the float64 value."""
    return round_half_away(Fraction(value) * Fraction(2) ** frac_bits)


def quantise_array(values: np.ndarray, frac_bits: int) -> np.ndarray:
    """Element-wise :func:`quantise`, exact: scaling by a power of two does not round in float64,
    ``|x| + 1/2`` is exact below 2**52, and from 2**52 on every float64 is already an integer."""
    scaled = np.asarray(values, dtype=np.float64) * math.ldexp(1.0, frac_bits)
    magnitude = np.abs(scaled)
    if np.any(magnitude >= 2.0**63):
        raise ValueError("value too large for int64")
    rounded = np.where(magnitude >= 2.0**52, magnitude, np.floor(magnitude + 0.5)).astype(np.int64)
    return np.where(scaled < 0, -rounded, rounded)


def rshift_round(x: np.ndarray | int, shift: int) -> np.ndarray:
    """``x / 2**shift`` rounded half away from zero (the C helper ``rshift_round``)."""
    x = np.asarray(x, dtype=np.int64)
    if shift == 0:
        return x.copy()
    magnitude = (np.abs(x) + (1 << (shift - 1))) >> shift
    return np.where(x < 0, -magnitude, magnitude)


def rdiv_round(num: np.ndarray | int, den: np.ndarray | int) -> np.ndarray:
    """``num / den`` (den > 0) rounded half away from zero (the C helper ``rdiv_round``)."""
    num = np.asarray(num, dtype=np.int64)
    den = np.asarray(den, dtype=np.int64)
    magnitude = (np.abs(num) + den // 2) // den
    return np.where(num < 0, -magnitude, magnitude)


def saturate(x: np.ndarray | int, lo: int, hi: int) -> np.ndarray:
    return np.minimum(np.maximum(np.asarray(x, dtype=np.int64), lo), hi)


def sat32(x: np.ndarray | int) -> np.ndarray:
    return saturate(x, INT32_MIN, INT32_MAX)


def headroom_bits(bound: float, limit: float) -> float:
    """log2(limit / bound): how many doublings the worst case may grow before saturating."""
    if bound <= 0:
        return math.inf
    return math.log2(limit / bound)
