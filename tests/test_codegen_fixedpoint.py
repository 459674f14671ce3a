"""Integer primitives of the code generator against exact arithmetic (fractions, math.tanh)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from codegen.activations import TANH_TABLE, activation_errors, sigmoid_q15, tanh_q15
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
    exact = np.minimum(np.tanh(k / 128.0) * 65536.0, 65535.0)
    assert np.max(np.abs(TANH_TABLE - exact)) <= 0.5 + 1e-9
    assert np.all(np.diff(TANH_TABLE) >= 0)


def test_integer_tanh_and_sigmoid_on_every_q16_input() -> None:
    """Exhaustive over [-12, 12] in Q15.16: the stated error bound holds, against math, not the table."""
    z = np.arange(-12 * 65536, 12 * 65536 + 1, dtype=np.int64)
    x = z / 65536.0
    t = tanh_q15(z, 16) / 32768.0
    s = sigmoid_q15(z, 16) / 32768.0
    exact_s = 1.0 / (1.0 + np.exp(-x))
    assert np.max(np.abs(t - np.tanh(x))) <= 1.0 / 32768  # the worst case is the cap at 32767
    assert np.max(np.abs(s - exact_s)) <= 1.0 / 32768
    inside = np.abs(x) < 4  # away from the cap: rounding (0.5) + table (0.25) + interpolation
    assert np.max(np.abs(t - np.tanh(x))[inside]) < 0.85 / 32768
    assert np.max(np.abs(s - exact_s)[inside]) < 0.7 / 32768
    assert abs(np.mean((t - np.tanh(x))[inside])) < 0.02 / 32768  # unbiased
    assert abs(np.mean((s - exact_s)[inside])) < 0.02 / 32768
    # structure the golden model and the bounds rely on: odd tanh, monotone both, ranges
    np.testing.assert_array_equal(tanh_q15(-z, 16), -tanh_q15(z, 16))
    assert np.all(np.diff(tanh_q15(z, 16)) >= 0) and np.all(np.diff(sigmoid_q15(z, 16)) >= 0)
    assert tanh_q15(z, 16).max() == 32767 and sigmoid_q15(z, 16).min() >= 0


@given(c=st.integers(-(2**31), 2**31 - 1))
def test_cell_tanh_on_q24_inputs(c: int) -> None:
    assert abs(int(tanh_q15(c, 24)) / 32768 - math.tanh(c / 2**24)) <= 1.0 / 32768


def test_reported_activation_errors_are_the_measured_ones() -> None:
    errors = activation_errors(16, 24)
    for kind in ("tanh", "sigmoid", "tanh_cell"):
        assert 0.5 < errors[kind].max_error_lsb <= 1.0  # rounding alone costs half an LSB
