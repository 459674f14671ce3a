"""Integer primitives of the code generator against exact arithmetic (fractions, math.tanh)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from codegen.activations import (
    ACT_ERROR_LSB,
    ACT_MAX,
    TABLE_STEP_BITS,
    TANH_TABLE,
    activation_errors,
    exact_sigmoid,
    exact_tanh,
    sigmoid_act,
    tanh_act,
)
from codegen.fixedpoint import quantise, quantise_array, rdiv_round, rshift_round

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


def test_tanh_table_matches_math_to_half_an_lsb() -> None:
    k = np.arange(TANH_TABLE.size)
    exact = np.minimum(np.tanh(k / 32.0) * 2.0**31, 2.0**31 - 1)
    assert np.max(np.abs(TANH_TABLE - exact)) <= 0.5 + 1e-6
    assert np.all(np.diff(TANH_TABLE) >= 0) and TANH_TABLE[-1] == 2**31 - 1


def _inputs(frac: int, limit: float) -> np.ndarray:
    """Every input within 1,000 LSB of each table knot (where the interpolation changes segment),
    an odd-strided grid over [-limit, limit] (every phase of the segments) and zero."""
    step = 1 << (frac - TABLE_STEP_BITS)
    knots = np.arange(0, int(limit * 32) + 1, dtype=np.int64) * step
    near = (knots[:, None] + np.arange(-1_000, 1_001)[None, :]).ravel()
    grid = np.arange(0, int(limit * 2**frac), 8_191, dtype=np.int64)
    z = np.unique(np.concatenate((near[near > 0], grid[1:])))
    return np.concatenate((-z[::-1], [0], z))


def test_integer_tanh_and_sigmoid_against_math() -> None:
    """Q5.26 inputs over [-14, 14] (tanh) and [-28, 28] (sigmoid), 1 .. 2 M points: the documented
    bound holds against math (not against the table), the mean error is 0, the structure the golden
    model and the bounds rely on holds."""
    for fn, exact, limit in ((tanh_act, exact_tanh, 14.0), (sigmoid_act, exact_sigmoid, 28.0)):
        z = _inputs(26, limit)
        y = fn(z, 26)
        err = y - exact(z, 26) * 2.0**30
        assert np.max(np.abs(err)) < 12 <= ACT_ERROR_LSB  # about 1.1e-8
        inside = np.abs(z) < 4 << 26
        assert abs(np.mean(err[inside])) < 0.05  # unbiased (LSB of Q30)
        assert y.max() == ACT_MAX  # the cap: a forget gate never reaches 1
        # never more than one LSB backwards, and only where the function is flat (slope < 1e-6)
        steps = np.diff(y)
        assert steps.min() >= -1
        back = exact(z[1:][steps < 0], 26)
        slope = 1 - back**2 if fn is tanh_act else back * (1 - back)
        assert np.all(slope < 1e-6)
    z = _inputs(26, 14.0)
    np.testing.assert_array_equal(tanh_act(-z, 26), -tanh_act(z, 26))  # exactly odd
    s = sigmoid_act(z, 26)
    assert s.min() >= 0 and np.all(np.abs(s + sigmoid_act(-z, 26) - 2**30) <= 1)


def test_activations_are_constant_beyond_the_table() -> None:
    """Why saturating z at +-32 (Q5.26) is exact: both functions are already constant there."""
    big = np.array([12 << 26, 24 << 26, 2**31 - 1, 2**31], dtype=np.int64)
    assert len(set(tanh_act(big, 26).tolist())) == 1 and len(set(tanh_act(-big, 26).tolist())) == 1
    assert len(set(sigmoid_act(big[1:], 26).tolist())) == 1
    assert len(set(sigmoid_act(-big[1:], 26).tolist())) == 1


@given(c=st.integers(-(2**31), 2**31 - 1))
def test_cell_tanh_on_q24_inputs(c: int) -> None:
    assert abs(int(tanh_act(c, 24)) - math.tanh(c / 2**24) * 2**30) < 12


def test_reported_activation_errors_are_the_measured_ones() -> None:
    errors = activation_errors(26, 24)
    for kind in ("tanh", "sigmoid", "tanh_cell"):
        assert 0.5 < errors[kind].max_error_lsb < 12  # rounding alone costs half an LSB
        assert abs(errors[kind].mean_error_lsb) < 0.05
