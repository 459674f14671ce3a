"""Tests of the Mantegna Lévy steps (eq. (14)-(15)): the sigma formula and the statistics.

Tail expectation used below (independent of the implementation): with
``X = sigma U / |V|**(1/beta)``, ``|X| > x`` iff ``|V| < (sigma |U| / x)**beta``, and
``P(|V| < e) = sqrt(2/pi) e (1 - e**2/6 + ...)``.  Hence for large ``x``::

    P(|X| > x) ~= C x**-beta,   C = sqrt(2/pi) sigma**beta E|U|**beta,
    E|U|**beta = 2**(beta/2) Gamma((beta+1)/2) / sqrt(pi),

a pure power law of index ``beta`` (relative error ~ (sigma/x)**(2 beta) / 6, negligible
for x >= 10).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from trainer.dlstm.optim.levy import levy_step, mantegna_sigma

N_SAMPLES = 2_000_000


def tail_constant(beta: float) -> float:
    sigma = mantegna_sigma(beta)
    mean_abs_normal_power = 2 ** (beta / 2) * math.gamma((beta + 1) / 2) / math.sqrt(math.pi)
    return math.sqrt(2 / math.pi) * sigma**beta * mean_abs_normal_power


@pytest.fixture(scope="module")
def sample() -> np.ndarray:
    return levy_step(np.random.default_rng(20230601), N_SAMPLES, beta=1.5)


def test_sigma_hand_value_for_beta_one_and_a_half() -> None:
    # Gamma(2.5) = 3 sqrt(pi) / 4 = 1.329340; sin(3 pi / 4) = sqrt(2)/2; Gamma(1.25) = 0.906402 (tables);
    # 2 ** 0.25 = 1.189207.  Ratio = 0.939986 / 1.616850 = 0.581369; ** (2/3) = 0.696575.
    ratio = (0.75 * math.sqrt(math.pi) * math.sqrt(2) / 2) / (1.5 * 0.9064024770554771 * 2**0.25)
    assert ratio == pytest.approx(0.581369, abs=1e-6)
    assert mantegna_sigma(1.5) == pytest.approx(ratio ** (2 / 3), rel=1e-12)
    assert mantegna_sigma(1.5) == pytest.approx(0.6966, abs=5e-5)


def test_sigma_is_one_for_beta_one() -> None:
    # Gamma(2) sin(pi/2) / (1 * Gamma(1) * 2**0) = 1: the Cauchy case needs no rescaling.
    assert mantegna_sigma(1.0) == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("beta", [0.0, 2.0, -1.0, 2.5])
def test_sigma_rejects_beta_outside_open_interval(beta: float) -> None:
    with pytest.raises(ValueError):
        mantegna_sigma(beta)


def test_step_is_ratio_of_the_two_gaussian_draws_in_order() -> None:
    draws = np.random.default_rng(5).standard_normal(8)
    expected = mantegna_sigma(1.5) * draws[:4] / np.abs(draws[4:]) ** (1 / 1.5)
    np.testing.assert_allclose(levy_step(np.random.default_rng(5), 4), expected, rtol=1e-15)


def test_shape_and_determinism() -> None:
    a = levy_step(np.random.default_rng(1), (3, 4))
    b = levy_step(np.random.default_rng(1), (3, 4))
    c = levy_step(np.random.default_rng(2), (3, 4))
    assert a.shape == (3, 4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_symmetric_about_zero(sample: np.ndarray) -> None:
    # Sign test: #positive ~ Binomial(n, 1/2); 5 standard deviations.
    positives = int(np.sum(sample > 0))
    assert abs(positives - N_SAMPLES / 2) < 5 * math.sqrt(N_SAMPLES / 4)
    assert abs(np.median(sample)) < 0.01
    # The two tails beyond 10 hold the same number of points (difference ~ sqrt(total)).
    right, left = int(np.sum(sample > 10)), int(np.sum(sample < -10))
    assert abs(right - left) < 5 * math.sqrt(right + left)


@pytest.mark.parametrize("threshold", [10.0, 50.0, 200.0])
def test_tail_fraction_matches_power_law(sample: np.ndarray, threshold: float) -> None:
    expected = N_SAMPLES * tail_constant(1.5) * threshold**-1.5
    observed = int(np.sum(np.abs(sample) > threshold))
    assert expected > 250  # enough counts for the Poisson tolerance to mean something
    assert abs(observed - expected) < 5 * math.sqrt(expected)


def test_tail_is_far_heavier_than_gaussian(sample: np.ndarray) -> None:
    # A Gaussian with the same sigma would put ~1e-46 of its mass beyond 10.
    assert np.mean(np.abs(sample) > 10) > 1e-3


@pytest.mark.parametrize("beta", [1.5, 1.2])
def test_hill_estimator_recovers_tail_index(beta: float) -> None:
    magnitudes = np.sort(np.abs(levy_step(np.random.default_rng(77), N_SAMPLES, beta=beta)))[::-1]
    k = 2000
    hill = 1.0 / np.mean(np.log(magnitudes[:k] / magnitudes[k]))
    # Standard error of the Hill estimator is beta / sqrt(k) ~= 0.034 at beta = 1.5.
    assert hill == pytest.approx(beta, abs=4 * beta / math.sqrt(k))
