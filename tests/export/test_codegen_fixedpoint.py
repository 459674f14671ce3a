"""Integer primitives of the code generator against exact arithmetic (fractions, math.tanh)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from codegen.activations import (
    ACT_ERROR_LSB,
    ACT_KNOT,
    T_MAX,
    activation_errors,
    exact_sigmoid,
    exact_tanh,
    sigmoid_q16,
    tanh_q15,
)
from codegen.fixedpoint import quantise, quantise_array, rdiv_round, rshift_round
from codegen.qformats import ACT_KNOTS, ACT_STEP_BITS

INT62 = st.integers(min_value=-(2**62), max_value=2**62)


def _round_half_away(q: Fraction) -> int:
    n = math.floor(abs(q) + Fraction(1, 2))
    return -n if q < 0 else n


@given(x=INT62, shift=st.integers(0, 60))
def test_rshift_round_is_division_rounded_half_away(x: int, shift: int) -> None:
    assert int(rshift_round(x, shift)) == _round_half_away(Fraction(x, 2**shift))


@given(num=INT62, den=st.integers(1, 2**31))
def test_rdiv_round_is_division_rounded_half_away(num: int, den: int) -> None:
    assert int(rdiv_round(num, den)) == _round_half_away(Fraction(num, den))


@given(value=st.floats(-1e6, 1e6, allow_nan=False), frac=st.integers(0, 30))
def test_quantise_array_equals_exact_scalar_quantise(value: float, frac: int) -> None:
    assert int(quantise_array(np.array([value]), frac)[0]) == quantise(value, frac)
    assert quantise(value, frac) == _round_half_away(Fraction(value) * 2**frac)


def test_ties_round_away_from_zero() -> None:
    assert rshift_round(np.array([3, -3, 1, -1, 2, -2]), 1).tolist() == [2, -2, 1, -1, 1, -1]
    assert rdiv_round(np.array([5, -5, 7, -7]), 2).tolist() == [3, -3, 4, -4]


def test_activation_table_is_the_documented_interpolant() -> None:
    """Every knot and every segment's midpoint against 2**15 (tanh(x) + 1) (math, not decimal):
    within the interpolation bound; the knots rise, the ends are flat and capped to 1 .. 65535."""
    x = -8.0 + np.arange(ACT_KNOTS) * 2.0**-ACT_STEP_BITS
    exact = 2.0**15 * (np.tanh(x) + 1)
    middle = (ACT_KNOT[:-1] + ACT_KNOT[1:]) / 2.0
    exact_middle = 2.0**15 * (np.tanh((x[:-1] + x[1:]) / 2) + 1)
    assert np.max(np.abs(ACT_KNOT - exact)) < 2.5  # h**2 max|T''| / 16 = 1.6, plus the rounding
    assert np.max(np.abs(middle - exact_middle)) < 2.5
    assert ACT_KNOT[0] == ACT_KNOT[1] and ACT_KNOT[-1] == ACT_KNOT[-2]  # flat first and last segments
    assert ACT_KNOT.min() >= 1 and ACT_KNOT.max() <= T_MAX and np.all(np.diff(ACT_KNOT) >= 0)


def _inputs(frac: int, limit: float) -> np.ndarray:
    """Every input within 300 LSB of each segment boundary, an odd-strided grid over [-limit,
    limit] (every position inside the segments) and zero."""
    step = 1 << (frac - ACT_STEP_BITS)
    knots = np.arange(0, int(limit * 2**ACT_STEP_BITS) + 1, dtype=np.int64) * step
    near = (knots[:, None] + np.arange(-300, 301)[None, :]).ravel()
    grid = np.arange(0, int(limit * 2**frac), 4_093, dtype=np.int64)
    z = np.unique(np.concatenate((near[near > 0], grid[1:])))
    return np.concatenate((-z[::-1], [0], z))


def test_integer_tanh_and_sigmoid_against_math() -> None:
    """Q26 inputs over [-10, 10] (tanh) and [-20, 20] (sigmoid): the documented bound holds
    against math, the mean error is small, the outputs stay in their documented ranges."""
    for fn, exact, limit, out_frac in (
        (tanh_q15, exact_tanh, 10.0, 15),
        (sigmoid_q16, exact_sigmoid, 20.0, 16),
    ):
        z = _inputs(26, limit)
        y = fn(z, 26 - ACT_STEP_BITS)
        err = y - exact(z, 26) * 2.0**out_frac
        assert np.max(np.abs(err)) < 3 < ACT_ERROR_LSB  # about 7.6e-5 (tanh), 3.5e-5 (sigmoid)
        assert abs(np.mean(err[np.abs(z) < 4 << 26])) < 0.1
        steps = np.diff(y)
        assert steps.min() >= -2  # nearly monotone: a segment end and the next start may differ by an LSB
    t = tanh_q15(_inputs(26, 10.0), 26 - ACT_STEP_BITS)
    s = sigmoid_q16(_inputs(26, 20.0), 26 - ACT_STEP_BITS)
    assert t.min() == -32767 and t.max() == 32767 and s.min() >= 1 and s.max() == T_MAX  # f < 1


def test_activations_are_constant_beyond_the_table() -> None:
    """The accumulator needs no saturation: beyond the table both functions are constant."""
    big = np.array([8 << 26, 16 << 26, 2**31 - 1], dtype=np.int64)
    for fn in (tanh_q15, sigmoid_q16):
        assert len(set(fn(big[1:], 21).tolist())) == 1 and len(set(fn(-big[1:], 21).tolist())) == 1


@given(c=st.integers(-(2**31), 2**31 - 1))
def test_cell_tanh_on_q24_inputs(c: int) -> None:
    assert abs(int(tanh_q15(c, 24 - ACT_STEP_BITS)) - math.tanh(c / 2**24) * 2**15) < 3


def test_reported_activation_errors_are_the_measured_ones() -> None:
    errors = activation_errors(26, 24)
    for kind in ("tanh", "sigmoid", "tanh_cell"):
        assert 0.5 < errors[kind].max_error_lsb < 3  # rounding alone costs half an LSB
        assert abs(errors[kind].mean_error_lsb) < 0.2
