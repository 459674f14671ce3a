"""Integer tanh and sigmoid without libm: one table of tanh with linear interpolation.

* ``TANH_TABLE[k] = round(65536 * tanh(k / 128))`` for ``k = 0 .. 1024`` (inputs 0 .. 8), capped at
  65535 so it fits uint16 (2,050 bytes of flash); computed with :mod:`decimal` (correctly rounded
  ``exp``), so the table is the same on every machine.
* ``tanh_raw``: for ``z`` with ``F`` fractional bits, ``m = |z|``, ``k = m >> (F - 7)``, linear
  interpolation between ``T[k]`` and ``T[k + 1]`` kept with 8 extra bits (Q24, floor), ``T[1024]``
  beyond 8. All unsigned.
* ``tanh(z)``: the raw value rounded once to Q15 (half up on the magnitude), capped at 32767, with
  the sign of ``z``: exactly odd.
* ``sigmoid(z) = (1 + tanh(z / 2)) / 2``: ``tanh_raw`` of the same integer read with one more
  fractional bit, then ``(2**24 + t) / 2`` rounded once to Q15 (a non-negative value), capped at
  32767. Rounding once, from the extra bits, keeps both functions unbiased: a floor or a second
  rounding step costs a quarter of an LSB of bias, which the recurrence accumulates (measured:
  twice the golden-versus-float error on a trained 2x10 DLSTM).

Outputs are Q15 in [-32767, 32767] and [0, 32767]; both functions are monotone non-decreasing in
``z`` (the table is monotone and interpolation preserves it), which the worst-case bounds of
:mod:`codegen.quantize` rely on.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from decimal import Decimal, localcontext

import numpy as np

ACT_FRAC = 15  # outputs are Q15
TABLE_FRAC = 16  # table entries are Q16
EXTRA_BITS = 8  # interpolation keeps 8 more bits: raw values are Q24
RAW_FRAC = TABLE_FRAC + EXTRA_BITS
TABLE_STEP_BITS = 7  # 128 table points per unit of input
TABLE_LAST = 1024  # table covers 0 .. 8
ONE_Q15 = 1 << ACT_FRAC
Q15_MAX = ONE_Q15 - 1


def _tanh_decimal(x: Decimal) -> Decimal:
    e = (2 * x).exp()
    return (e - 1) / (e + 1)


def _build_table() -> np.ndarray:
    values = []
    with localcontext() as ctx:
        ctx.prec = 40
        for k in range(TABLE_LAST + 1):
            t = _tanh_decimal(Decimal(k) / Decimal(1 << TABLE_STEP_BITS)) * (1 << TABLE_FRAC)
            values.append(min(int(t + Decimal("0.5")), (1 << TABLE_FRAC) - 1))  # t >= 0: floor(t + 1/2)
    return np.asarray(values, dtype=np.int64)


TANH_TABLE = _build_table()


def tanh_raw(magnitude: np.ndarray, frac_bits: int) -> np.ndarray:
    """tanh of a non-negative value with ``frac_bits`` fractional bits, Q24 (the C ``tanh_raw``)."""
    shift = frac_bits - TABLE_STEP_BITS
    if shift < EXTRA_BITS:
        raise ValueError(f"tanh input needs at least {TABLE_STEP_BITS + EXTRA_BITS} fractional bits")
    magnitude = np.asarray(magnitude, dtype=np.int64)
    index = magnitude >> shift
    k = np.minimum(index, TABLE_LAST - 1)
    lo, hi = TANH_TABLE[k], TANH_TABLE[k + 1]
    frac = magnitude & ((1 << shift) - 1)
    interpolated = (lo << EXTRA_BITS) + (((hi - lo) * frac) >> (shift - EXTRA_BITS))
    return np.where(index < TABLE_LAST, interpolated, TANH_TABLE[TABLE_LAST] << EXTRA_BITS)


def tanh_q15(z: np.ndarray, frac_bits: int) -> np.ndarray:
    """tanh in Q15 of ``z`` with ``frac_bits`` fractional bits (the C ``tanh_q15``)."""
    z = np.asarray(z, dtype=np.int64)
    shift = RAW_FRAC - ACT_FRAC
    t = np.minimum((tanh_raw(np.abs(z), frac_bits) + (1 << (shift - 1))) >> shift, Q15_MAX)
    return np.where(z < 0, -t, t)


def sigmoid_q15(z: np.ndarray, frac_bits: int) -> np.ndarray:
    """``(1 + tanh(z / 2)) / 2`` in Q15 (the C ``sigmoid_q15``)."""
    z = np.asarray(z, dtype=np.int64)
    raw = tanh_raw(np.abs(z), frac_bits + 1)
    signed = np.where(z < 0, -raw, raw)
    shift = RAW_FRAC + 1 - ACT_FRAC
    return np.minimum(((1 << RAW_FRAC) + signed + (1 << (shift - 1))) >> shift, Q15_MAX)


@dataclass(frozen=True)
class ActivationError:
    """Largest |integer - exact| over a grid of inputs, in Q15 LSBs and absolute."""

    max_error_lsb: float
    points: int
    input_frac_bits: int
    input_range: tuple[float, float]

    @property
    def max_abs_error(self) -> float:
        return self.max_error_lsb / ONE_Q15

    def to_dict(self) -> dict[str, object]:
        return {
            "max_abs_error": float(f"{self.max_abs_error:.6g}"),
            "max_error_lsb_q15": float(f"{self.max_error_lsb:.6g}"),
            "grid_points": self.points,
            "input_frac_bits": self.input_frac_bits,
            "input_range": list(self.input_range),
        }


def _error(kind: str, frac_bits: int, limit: float, stride: int = 1) -> ActivationError:
    top = int(limit * (1 << frac_bits))
    z = np.arange(-top, top + 1, stride, dtype=np.int64)
    x = z / float(1 << frac_bits)
    if kind == "tanh":
        exact, approx = np.tanh(x), tanh_q15(z, frac_bits)
    else:
        exact, approx = 0.5 * (1.0 + np.tanh(0.5 * x)), sigmoid_q15(z, frac_bits)
    err = np.max(np.abs(approx / ONE_Q15 - exact)) * ONE_Q15
    return ActivationError(float(err), int(z.size), frac_bits, (-limit, limit))


@functools.cache
def activation_errors(z_frac: int, c_frac: int) -> dict[str, ActivationError]:
    """Measured worst errors: gates on every Q``z_frac`` input in [-10, 10] (tanh) or [-20, 20] (sigmoid), the cell tanh on a
    strided Q``c_frac`` grid (every 97th point, which is odd so it walks all interpolation phases)."""
    return {
        "tanh": _error("tanh", z_frac, 10.0),
        "sigmoid": _error("sigmoid", z_frac, 20.0),
        "tanh_cell": _error("tanh", c_frac, 10.0, stride=97),
    }
