"""Integer tanh and sigmoid without libm: one table of tanh with cubic Hermite interpolation.

* ``TANH_TABLE[k] = round(2**31 * tanh(k / 32))`` for ``k = 0 .. 384`` (inputs 0 .. 12), capped at
  ``2**31 - 1`` (uint32, 1,540 bytes of flash); computed with :mod:`decimal` (correctly rounded
  ``exp``), so the table is the same on every machine. Beyond 12, tanh is 1 to within 2**-33.
* ``tanh_raw``: for a magnitude ``m`` with ``F`` fractional bits, segment ``k = m >> (F - 5)`` and
  position ``s`` (the low ``F - 5`` bits), the cubic Hermite interpolant between ``T[k]`` and
  ``T[k + 1]``. The slopes come from the table itself, ``tanh' = 1 - tanh**2``, so no second table
  is needed; the cubic is evaluated by Horner in Q39 (8 bits below the table) with a rounding
  shift per step, and clamped to ``[0, T[384] * 2**8]``. Why cubic: linear interpolation needs
  2**-8 steps (a 24 KB table) for the same 1e-8 accuracy; the Hermite error is
  ``h**4 max|tanh^(4)| / 384`` = 1e-8 at ``h = 1/32``.
* ``tanh(z)``: the raw value rounded once to Q30 (half up on the magnitude), capped at
  ``2**30 - 1``, with the sign of ``z``: exactly odd.
* ``sigmoid(z) = (1 + tanh(z / 2)) / 2``: ``tanh_raw`` of the same integer read with one more
  fractional bit, then ``(2**39 +- raw) / 2`` rounded once to Q30 (a non-negative value), capped at
  ``2**30 - 1`` (so a forget gate is always below 1). Rounding once keeps both functions unbiased.

Outputs are Q30 in ``[-(2**30 - 1), 2**30 - 1]`` and ``[0, 2**30 - 1]``. Both are constant beyond
the table (|z| >= 12 for tanh, >= 24 for sigmoid), which makes the saturation of the Q5.26
pre-activation at +-32 exactly harmless. Error bound: the Hermite remainder
``h**4 max|tanh^(4)| / 384`` (max|tanh^(4)| = 4.09) is 10.9 LSB of Q30, the table's rounding 0.25,
the floored slopes below 0.1, the Horner steps 2**-8, the final rounding 0.5: below 12 LSB (1.1e-8)
in all, which the tests confirm on millions of inputs (measured 11.4); the mean error is 0.
Monotonicity is not exact (a Hermite interpolant with rounded coefficients may step back by an LSB
where the function is flat), so the worst-case bounds of :mod:`codegen.quantize` add
:data:`ACT_ERROR_LSB` instead of relying on it.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from decimal import Decimal, localcontext

import numpy as np

from codegen.fixedpoint import rshift_round

ACT_FRAC = 30  # gates, tanh, sigmoid and h are Q30
TABLE_FRAC = 31  # table entries are Q31 (uint32)
EXTRA_BITS = 8  # the Hermite cubic is evaluated in Q39
RAW_FRAC = TABLE_FRAC + EXTRA_BITS
TABLE_STEP_BITS = 5  # 32 table points per unit of input
TABLE_LAST = 384  # the table covers 0 .. 12
TABLE_MAX = (1 << TABLE_FRAC) - 1
RAW_MAX = TABLE_MAX << EXTRA_BITS
ONE = 1 << ACT_FRAC
ACT_MAX = ONE - 1
ACT_ERROR_LSB = 16  # bound of |integer - exact| in Q30 LSB used by the proofs (analytic < 12)
SLOPE_SHIFT = TABLE_FRAC + TABLE_STEP_BITS  # (2**62 - T**2) >> 36: h tanh' = h (1 - tanh**2) in Q31


def _tanh_decimal(x: Decimal) -> Decimal:
    e = (2 * x).exp()
    return (e - 1) / (e + 1)


def _build_table() -> np.ndarray:
    values = []
    with localcontext() as ctx:
        ctx.prec = 50
        for k in range(TABLE_LAST + 1):
            t = _tanh_decimal(Decimal(k) / Decimal(1 << TABLE_STEP_BITS)) * (1 << TABLE_FRAC)
            values.append(min(int(t + Decimal("0.5")), TABLE_MAX))  # t >= 0: floor(t + 1/2)
    return np.asarray(values, dtype=np.int64)


TANH_TABLE = _build_table()


def tanh_raw(magnitude: np.ndarray, frac_bits: int) -> np.ndarray:
    """tanh of a non-negative value with ``frac_bits`` fractional bits, Q39 (the C ``tanh_raw``)."""
    shift = frac_bits - TABLE_STEP_BITS
    if not 1 <= shift <= 22:
        raise ValueError(f"tanh input needs {TABLE_STEP_BITS + 1} .. {TABLE_STEP_BITS + 22} fractional bits")
    magnitude = np.asarray(magnitude, dtype=np.int64)
    index = magnitude >> shift
    k = np.minimum(index, TABLE_LAST - 1)
    y0, y1 = TANH_TABLE[k], TANH_TABLE[k + 1]
    s = magnitude & ((1 << shift) - 1)
    one_q62 = np.uint64(1 << (2 * TABLE_FRAC))
    d0 = ((one_q62 - (y0 * y0).astype(np.uint64)) >> np.uint64(SLOPE_SHIFT)).astype(np.int64)
    d1 = ((one_q62 - (y1 * y1).astype(np.uint64)) >> np.uint64(SLOPE_SHIFT)).astype(np.int64)
    delta = y1 - y0
    lift = 1 << EXTRA_BITS
    acc = (d0 + d1 - 2 * delta) * lift
    acc = (3 * delta - 2 * d0 - d1) * lift + rshift_round(acc * s, shift)
    acc = d0 * lift + rshift_round(acc * s, shift)
    acc = y0 * lift + rshift_round(acc * s, shift)
    return np.where(index < TABLE_LAST, np.clip(acc, 0, RAW_MAX), TANH_TABLE[TABLE_LAST] << EXTRA_BITS)


def tanh_act(z: np.ndarray, frac_bits: int) -> np.ndarray:
    """tanh in Q30 of ``z`` with ``frac_bits`` fractional bits (the C ``tanh_q30``)."""
    z = np.asarray(z, dtype=np.int64)
    shift = RAW_FRAC - ACT_FRAC
    t = np.minimum((tanh_raw(np.abs(z), frac_bits) + (1 << (shift - 1))) >> shift, ACT_MAX)
    return np.where(z < 0, -t, t)


def sigmoid_act(z: np.ndarray, frac_bits: int) -> np.ndarray:
    """``(1 + tanh(z / 2)) / 2`` in Q30 (the C ``sigmoid_q30``)."""
    z = np.asarray(z, dtype=np.int64)
    raw = tanh_raw(np.abs(z), frac_bits + 1)
    signed = np.where(z < 0, -raw, raw)
    shift = RAW_FRAC + 1 - ACT_FRAC
    return np.minimum(((1 << RAW_FRAC) + signed + (1 << (shift - 1))) >> shift, ACT_MAX)


@dataclass(frozen=True)
class ActivationError:
    """Largest |integer - exact| over a grid of inputs and the mean over its inner half, in Q30 LSBs."""

    max_error_lsb: float
    mean_error_lsb: float
    points: int
    input_frac_bits: int
    input_range: tuple[float, float]

    @property
    def max_abs_error(self) -> float:
        return self.max_error_lsb / ONE

    def to_dict(self) -> dict[str, object]:
        return {
            "max_abs_error": float(f"{self.max_abs_error:.6g}"),
            "max_error_lsb_q30": float(f"{self.max_error_lsb:.6g}"),
            "mean_error_lsb_q30": float(f"{self.mean_error_lsb:.3g}"),
            "grid_points": self.points,
            "input_frac_bits": self.input_frac_bits,
            "input_range": list(self.input_range),
        }


def exact_tanh(z: np.ndarray, frac_bits: int) -> np.ndarray:
    return np.tanh(np.asarray(z, dtype=np.float64) / 2.0**frac_bits)


def exact_sigmoid(z: np.ndarray, frac_bits: int) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * np.asarray(z, dtype=np.float64) / 2.0**frac_bits))


def _error(kind: str, frac_bits: int, limit: float, stride: int) -> ActivationError:
    top = int(limit * (1 << frac_bits))
    z = np.arange(-top, top + 1, stride, dtype=np.int64)
    if kind == "tanh":
        exact, approx = exact_tanh(z, frac_bits), tanh_act(z, frac_bits)
    else:
        exact, approx = exact_sigmoid(z, frac_bits), sigmoid_act(z, frac_bits)
    err = approx - exact * ONE  # float64: 2**-23 LSB of resolution, ample
    inner = np.abs(z) <= top // 2  # the mean away from the cap at 2**30 - 1 (which is biased by design)
    return ActivationError(
        float(np.max(np.abs(err))), float(np.mean(err[inner])), int(z.size), frac_bits, (-limit, limit)
    )


@functools.cache
def activation_errors(z_frac: int, c_frac: int) -> dict[str, ActivationError]:
    """Measured errors on strided grids (odd strides, so they walk all interpolation phases):
    gates on Q``z_frac`` inputs in [-14, 14] (tanh) or [-28, 28] (sigmoid), the cell tanh on
    Q``c_frac`` inputs in [-14, 14]."""
    return {
        "tanh": _error("tanh", z_frac, 14.0, 1_001),
        "sigmoid": _error("sigmoid", z_frac, 28.0, 2_003),
        "tanh_cell": _error("tanh", c_frac, 14.0, 251),
    }
