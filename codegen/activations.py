"""Integer tanh and sigmoid from one table with linear interpolation, knots computed offline.

* The table holds ``T(x) = 2**15 (tanh(x) + 1) = 2**16 sigmoid(2x)`` on ``x`` in [-8, 8) in
  :data:`ACT_SEGMENTS` = 512 segments of 1/32 (``codegen.qformats``) as :data:`ACT_KNOTS` = 513
  knots (uint16, 1 KB): the knot at each segment end is T there moved by half the mean of the
  chord deviations at the midpoints of its two segments (the continuous line then splits each
  chord's error around zero, like the minimax line of a function whose curvature is nearly
  constant over 1/16); knots are computed with :mod:`decimal` (correctly rounded ``exp``), so the
  table is the same on every machine. The first and last segments are flat, which makes any input
  beyond the table need no special case. A continuous line needs no slope column: half the flash
  of a start-value-and-slope table at the same error (2.5 LSB).
* ``act(acc, shift)``: the input is ``acc / 2**(shift + 5)``; segment ``k = floor(acc / 2**shift)
  + 256`` clamped to 0 .. 511, position the 12 bits below it; ``T = v[k] + ((v[k+1] - v[k]) pos +
  2**11) >> 12`` (the knots rise, so the difference is unsigned). No 64-bit arithmetic, no branch
  but the clamp (none for a gate whose accumulator cannot leave the table): on a Cortex-M4 one
  load of both knots, one SMLABB, 7 or 8 instructions.
* ``tanh = T - 2**15`` (Q15, -32767 .. 32767); ``sigmoid(z) = T(z / 2)`` (Q16, 1 .. 65535: a
  forget gate stays below 1), the same table read with one more shift bit.

Error (measured on every segment and position by the tests, quoted in the manifest): the line's
own error (h**2 max|T''| / 16, 1.6 LSB of Q15 at the steepest curvature), the rounding of the
knots and the dropped input bits below the position: below 3 LSB of the output format (Q15 for
tanh, Q16 for sigmoid), i.e. 7.6e-5 for tanh (measured 2.5 LSB); the proofs use
:data:`ACT_ERROR_LSB`. Why 1/32 and not 1/16: with 1/16 (7 LSB) the activations alone cost
1.4e-3 mg RMS on a trained 2x10 network, above the 1e-3 mg budget. The golden functions here are
an independent numpy implementation of the same arithmetic (floor divisions on int64, not the C's
offset tricks), compared with the C library bit for bit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from decimal import Decimal, localcontext

import numpy as np

from codegen.qformats import (
    ACT_KNOTS,
    ACT_ONE,
    ACT_POS_BITS,
    ACT_RANGE,
    ACT_SEGMENTS,
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


def _build_knots() -> np.ndarray:
    knots = []
    step = Decimal(1) / Decimal(1 << ACT_STEP_BITS)
    with localcontext() as ctx:
        ctx.prec = 40
        edges = [_t_decimal(Decimal(-ACT_RANGE) + k * step) for k in range(ACT_KNOTS)]
        middles = [_t_decimal(Decimal(-ACT_RANGE) + k * step + step / 2) for k in range(ACT_SEGMENTS)]
        # chord error at each segment's midpoint; a knot moves by half the mean of its two segments'
        deviation = [m - (t0 + t1) / 2 for m, t0, t1 in zip(middles, edges, edges[1:], strict=False)]
        for k in range(ACT_KNOTS):
            if k in (0, ACT_KNOTS - 1):
                continue
            knots.append(_round(edges[k] + (deviation[k - 1] + deviation[k]) / 4))
    knots = [max(T_MIN, min(v, T_MAX)) for v in knots]
    # flat first and last segments: inputs beyond the table land there, whatever their position
    return np.asarray([knots[0], *knots, knots[-1]], dtype=np.int64)


ACT_KNOT = _build_knots()
assert ACT_KNOT.size == ACT_KNOTS and ACT_KNOT.min() >= T_MIN and ACT_KNOT.max() <= T_MAX
assert np.all(np.diff(ACT_KNOT) >= 0)  # monotone: the C's knot differences are unsigned


def act(acc: np.ndarray | int, shift: int) -> np.ndarray:
    """T (Q15 of tanh + 1) of ``acc / 2**(shift + ACT_STEP_BITS)`` (the C ``tdck_act``)."""
    if not ACT_POS_BITS <= shift <= 30:
        raise ValueError(f"activation shift {shift} outside {ACT_POS_BITS} .. 30")
    acc = np.asarray(acc, dtype=np.int64)
    k = np.clip((acc >> shift) + ACT_SEGMENTS // 2, 0, ACT_SEGMENTS - 1)  # numpy >>: floor division
    pos = (acc >> (shift - ACT_POS_BITS)) & ((1 << ACT_POS_BITS) - 1)
    v0 = ACT_KNOT[k]
    return v0 + (((ACT_KNOT[k + 1] - v0) * pos + (1 << (ACT_POS_BITS - 1))) >> ACT_POS_BITS)


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
