"""Integer tanh and sigmoid from one table with linear interpolation, coefficients computed offline.

* The table holds ``T(x) = 2**15 (tanh(x) + 1) = 2**16 sigmoid(2x)`` on ``x`` in [-8, 8) in
  :data:`ACT_SEGMENTS` = 512 segments of 1/32 (``codegen.qformats``): per segment a start value
  (uint16) and a slope (uint16, 16 bits below the output LSB per position step). The line of each
  segment is the chord shifted by half the chord's deviation at the midpoint (the minimax line of a
  function whose curvature is nearly constant over 1/16); values and slopes are computed with
  :mod:`decimal` (correctly rounded ``exp``), so the table is the same on every machine. The first
  and last segments are flat, which makes any input beyond the table need no special case.
* ``act(acc, shift)``: the input is ``acc / 2**(shift + 5)``; segment ``k = floor(acc / 2**shift)
  + 256`` clamped to 0 .. 511, position the 12 bits below it; ``T = value[k] + (slope[k] pos +
  2**15) >> 16``. No 64-bit arithmetic, no branch but the clamp: 8 instructions on a Cortex-M4.
* ``tanh = T - 2**15`` (Q15, -32767 .. 32767); ``sigmoid(z) = T(z / 2)`` (Q16, 1 .. 65535: a
  forget gate stays below 1), the same table read with one more shift bit.

Error (measured on every segment and position by the tests, quoted in the manifest): the line's
own error (h**2 max|T''| / 16, 1.6 LSB of Q15 at the steepest curvature), the rounding of value
and slope and the dropped input bits below the position: below 3 LSB of the output format (Q15
for tanh, Q16 for sigmoid), i.e. 7.6e-5 for tanh (measured 2.5 LSB); the proofs use :data:`ACT_ERROR_LSB`. Why 1/32 and
not 1/16 (half the flash): with 1/16 (7 LSB) the activations alone cost 1.4e-3 mg RMS on a trained
2x10 network, above the 1e-3 mg budget; with 1/32 the total is 4.4e-4 mg. The golden functions here are an
independent numpy implementation of the same arithmetic (floor divisions on int64, not the C's
offset trick), compared with the C library bit for bit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from decimal import Decimal, localcontext

import numpy as np

from codegen.qformats import (
    ACT_ONE,
    ACT_POS_BITS,
    ACT_RANGE,
    ACT_SEGMENTS,
    ACT_SLOPE_BITS,
    ACT_STEP_BITS,
    ACT_VALUE_FRAC,
    GATE_FRAC,
    TANH_FRAC,
)

T_MAX = (1 << 16) - 1  # T in 1 .. 65535: tanh in -32767 .. 32767, sigmoid below 1
T_MIN = 1
ACT_ERROR_LSB = 4  # bound of |integer - exact| in LSB of the output (Q15 tanh, Q16 sigmoid) the proofs use


def _t_decimal(x: Decimal) -> Decimal:
    """2**15 (tanh(x) + 1) = 2**16 / (1 + exp(-2x))."""
    return Decimal(1 << (ACT_VALUE_FRAC + 1)) / (1 + (-2 * x).exp())


def _round(value: Decimal) -> int:
    return int(value.to_integral_value(rounding="ROUND_HALF_UP"))


def _build_table() -> tuple[np.ndarray, np.ndarray]:
    values, slopes = [], []
    step = Decimal(1) / Decimal(1 << ACT_STEP_BITS)
    pos_top = (1 << ACT_POS_BITS) - 1
    with localcontext() as ctx:
        ctx.prec = 40
        for k in range(ACT_SEGMENTS):
            x0 = Decimal(-ACT_RANGE) + k * step
            t0, tm, t1 = _t_decimal(x0), _t_decimal(x0 + step / 2), _t_decimal(x0 + step)
            if k in (0, ACT_SEGMENTS - 1):  # flat: inputs beyond the table land here
                value, slope = _round(tm), 0
            else:
                deviation = tm - (t0 + t1) / 2  # chord error at the midpoint; the line takes half of it
                value = _round(t0 + deviation / 2)
                slope = _round((t1 - t0) * (1 << (ACT_SLOPE_BITS - ACT_POS_BITS)))
            value = max(T_MIN, min(value, T_MAX))
            top = value + ((slope * pos_top + (1 << (ACT_SLOPE_BITS - 1))) >> ACT_SLOPE_BITS)
            value -= max(0, top - T_MAX)  # cap the segment's end at T_MAX
            values.append(value)
            slopes.append(slope)
    return np.asarray(values, dtype=np.int64), np.asarray(slopes, dtype=np.int64)


ACT_VALUE, ACT_SLOPE = _build_table()
assert ACT_VALUE.min() >= T_MIN and ACT_SLOPE.max() <= 0xFFFF and ACT_SLOPE.min() >= 0


def act(acc: np.ndarray | int, shift: int) -> np.ndarray:
    """T (Q15 of tanh + 1) of ``acc / 2**(shift + ACT_STEP_BITS)`` (the C ``tdck_act``)."""
    if not ACT_POS_BITS <= shift <= 30:
        raise ValueError(f"activation shift {shift} outside {ACT_POS_BITS} .. 30")
    acc = np.asarray(acc, dtype=np.int64)
    k = np.clip((acc >> shift) + ACT_SEGMENTS // 2, 0, ACT_SEGMENTS - 1)  # numpy >>: floor division
    pos = (acc >> (shift - ACT_POS_BITS)) & ((1 << ACT_POS_BITS) - 1)
    return ACT_VALUE[k] + ((ACT_SLOPE[k] * pos + (1 << (ACT_SLOPE_BITS - 1))) >> ACT_SLOPE_BITS)


def sigmoid_q16(acc: np.ndarray | int, shift: int) -> np.ndarray:
    """sigmoid in Q16 of ``acc / 2**(shift + ACT_STEP_BITS)``."""
    return act(acc, shift + 1)


def tanh_q15(acc: np.ndarray | int, shift: int) -> np.ndarray:
    """tanh in Q15 of ``acc / 2**(shift + ACT_STEP_BITS)``."""
    return act(acc, shift) - ACT_ONE


@dataclass(frozen=True)
class ActivationError:
    """Largest |integer - exact| over a grid of inputs and the mean over its inner half, in output LSBs."""

    max_error_lsb: float
    mean_error_lsb: float
    points: int
    input_frac_bits: int
    output_frac_bits: int
    input_range: tuple[float, float]

    @property
    def max_abs_error(self) -> float:
        return self.max_error_lsb / 2.0**self.output_frac_bits

    def to_dict(self) -> dict[str, object]:
        return {
            "max_abs_error": float(f"{self.max_abs_error:.6g}"),
            "max_error_lsb": float(f"{self.max_error_lsb:.6g}"),
            "mean_error_lsb": float(f"{self.mean_error_lsb:.3g}"),
            "output_frac_bits": self.output_frac_bits,
            "grid_points": self.points,
            "input_frac_bits": self.input_frac_bits,
            "input_range": list(self.input_range),
        }


def exact_tanh(acc: np.ndarray, frac_bits: int) -> np.ndarray:
    return np.tanh(np.asarray(acc, dtype=np.float64) / 2.0**frac_bits)


def exact_sigmoid(acc: np.ndarray, frac_bits: int) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * np.asarray(acc, dtype=np.float64) / 2.0**frac_bits))


def _error(kind: str, frac_bits: int, limit: float, stride: int) -> ActivationError:
    top = int(limit * (1 << frac_bits))
    z = np.arange(-top, top + 1, stride, dtype=np.int64)
    shift = frac_bits - ACT_STEP_BITS
    if kind == "tanh":
        out_frac, exact, approx = TANH_FRAC, exact_tanh(z, frac_bits), tanh_q15(z, shift)
    else:
        out_frac, exact, approx = GATE_FRAC, exact_sigmoid(z, frac_bits), sigmoid_q16(z, shift)
    err = approx - exact * 2.0**out_frac
    inner = np.abs(z) <= top // 2
    return ActivationError(
        float(np.max(np.abs(err))),
        float(np.mean(err[inner])),
        int(z.size),
        frac_bits,
        out_frac,
        (-limit, limit),
    )


@functools.cache
def activation_errors(acc_frac: int, c_frac: int) -> dict[str, ActivationError]:
    """Measured errors on strided grids (odd strides walk all positions): gates on Q``acc_frac``
    inputs in [-10, 10] (tanh) or [-20, 20] (sigmoid), the cell's tanh on Q``c_frac`` in [-10, 10]."""
    return {
        "tanh": _error("tanh", acc_frac, 10.0, (1 << max(acc_frac - 16, 0)) * 7 + 1),
        "sigmoid": _error("sigmoid", acc_frac, 20.0, (1 << max(acc_frac - 15, 0)) * 7 + 1),
        "tanh_cell": _error("tanh", c_frac, 10.0, (1 << max(c_frac - 16, 0)) * 7 + 1),
    }
