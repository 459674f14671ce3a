"""Each IEEE-952 noise term alone, its coefficient read back from allantools' overlapping ADEV.

The reading logic (fixed-slope fit, "read at" points of the catalogue) is written here on
purpose, independent of the production Allan analysis.
"""

from __future__ import annotations

import math

import allantools
import numpy as np
import pytest

from trainer.physics.config import (
    NoiseConfig,
    PhysicsConfig,
    ProtocolConfig,
    RecordingConfig,
    TemperatureConfig,
)
from trainer.physics.noise import ar1_allan_variance, bias_instability_allan_variance, noise_term
from trainer.physics.profiles import SegmentSpec
from trainer.physics.simulate import simulate

TOLERANCE = 0.10  # catalogue: coefficient recovered within 10 %


def oadev(
    y: np.ndarray, fs: float, tau_min: float, tau_max: float, count: int = 40
) -> tuple[np.ndarray, np.ndarray]:
    taus = np.logspace(math.log10(tau_min), math.log10(tau_max), count)
    tau_out, dev, _, _ = allantools.oadev(y, rate=fs, data_type="freq", taus=taus)
    return np.asarray(tau_out), np.asarray(dev)


def fixed_slope_constant(taus: np.ndarray, dev: np.ndarray, slope: float) -> float:
    """C of the line sigma = C tau^slope fitted in log-log with the slope held fixed."""
    return float(np.exp(np.mean(np.log(dev) - slope * np.log(taus))))


def generate(identifier: str, params: dict[str, float], fs: float, n: int, seed: int = 7) -> np.ndarray:
    return noise_term(identifier, params, n, 1.0 / fs, np.random.default_rng(seed))


# (identifier, parameter, true value, slope, read-at tau, fs, samples, tau range)
CASES = [
    ("white_noise", "n_mg_rt_s", 0.025, -0.5, 1.0, 200.0, 240_000, (0.05, 10.0)),
    ("quantization_noise", "q_mg", 0.004, -1.0, math.sqrt(3.0), 200.0, 240_000, (0.05, 10.0)),
    # discrete random walk: sigma^2 = k^2 tau/3 + k^2 dt/(6m); from m >= 10 the extra term is < 0.2 %
    ("rate_random_walk", "k_mg_per_rt_s", 5e-4, 0.5, 3.0, 10.0, 400_000, (1.0, 100.0)),
    ("rate_ramp", "r_mg_per_s", 2e-5, 1.0, math.sqrt(2.0), 10.0, 50_000, (0.1, 500.0)),
]


@pytest.mark.parametrize(("identifier", "name", "true", "slope", "read_at", "fs", "n", "tau_range"), CASES)
def test_coefficient_recovered_from_allan_deviation(
    identifier: str, name: str, true: float, slope: float, read_at: float, fs: float, n: int, tau_range: tuple
) -> None:
    y = generate(identifier, {name: true}, fs, n)
    taus, dev = oadev(y, fs, *tau_range)
    constant = fixed_slope_constant(taus, dev, slope)
    recovered = constant * read_at**slope
    print(f"{identifier}: true {true:.4g}, recovered {recovered:.4g} ({recovered / true - 1:+.2%})")
    assert recovered == pytest.approx(true, rel=TOLERANCE)
    # and the local slope really is the signature slope
    fitted_slope = np.polyfit(np.log(taus), np.log(dev), 1)[0]
    assert fitted_slope == pytest.approx(slope, abs=0.05)


def test_bias_instability_floor_is_flat_over_three_decades_and_reads_b() -> None:
    b = 0.02
    fs, n = 10.0, 1_000_000  # tau from 0.1 s to 100 s keeps >= 1000 clusters per tau
    y = generate("bias_instability", {"b_mg": b}, fs, n)
    taus, dev = oadev(y, fs, 0.1, 100.0)
    recovered = dev.min() / 0.664
    print(f"bias_instability: true {b:.4g}, recovered {recovered:.4g} ({recovered / b - 1:+.2%})")
    assert recovered == pytest.approx(b, rel=TOLERANCE)
    assert np.all(np.abs(dev / (0.664 * b) - 1.0) < TOLERANCE)  # flat over all three decades
    assert abs(np.polyfit(np.log(taus), np.log(dev), 1)[0]) < 0.02


def _ar1_allan_variance_by_sums(m: int, a: float) -> float:
    """Allan variance of a unit AR(1) from its autocovariance a^|k|, summed term by term."""
    idx = np.arange(2 * m)
    cov = a ** np.abs(idx[:, None] - idx[None, :])
    weights = np.concatenate([-np.ones(m), np.ones(m)]) / m  # second cluster mean minus first
    return 0.5 * float(weights @ cov @ weights)


@pytest.mark.parametrize(("m", "tc_over_dt"), [(1, 0.5), (3, 2.0), (10, 10.0), (50, 3.0), (40, 1000.0)])
def test_ar1_allan_variance_formula(m: int, tc_over_dt: float) -> None:
    expected = _ar1_allan_variance_by_sums(m, math.exp(-1.0 / tc_over_dt))
    assert ar1_allan_variance(np.array([m]), 1.0, tc_over_dt)[0] == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("fs", [200.0, 10.0, 1.0])
def test_bias_instability_design_is_flat_from_one_sample_to_1e4_s(fs: float) -> None:
    taus = np.logspace(math.log10(1.0 / fs), 4.0, 200)
    adev = np.sqrt(bias_instability_allan_variance(taus, 1.0 / fs, 1.0e4))
    floor = math.sqrt(2.0 * math.log(2.0) / math.pi)  # 0.664
    assert np.all(np.abs(adev / floor - 1.0) < 0.02)


def test_white_noise_sample_variance() -> None:
    n, fs = 200_000, 200.0
    y = generate("white_noise", {"n_mg_rt_s": 0.03}, fs, n)
    assert np.std(y) == pytest.approx(0.03 * math.sqrt(fs), rel=0.01)


def test_rate_ramp_is_the_deterministic_trend() -> None:
    y = generate("rate_ramp", {"r_mg_per_s": -3e-5}, 10.0, 100)
    assert y == pytest.approx(-3e-5 * np.arange(100) / 10.0, abs=1e-15)


def _config(noise: tuple[NoiseConfig, ...]) -> PhysicsConfig:
    return PhysicsConfig(
        recording=RecordingConfig(sample_rate_hz=50.0),
        protocol=ProtocolConfig("custom", 20.0, (SegmentSpec("hold", 400.0, 20.0),)),
        temperature=TemperatureConfig(case_tau_s=60.0, temp_noise_c=0.05),
        noise=noise,
    )


def test_simulator_noise_column_is_the_generator_output() -> None:
    """Wiring: with one term on, true_noise_mg is that term's generator fed its own stream."""
    term = NoiseConfig("white_noise", {"n_mg_rt_s": 0.02})
    rec = simulate(_config((term,)), seed=11)
    taus, dev = oadev(rec.columns["true_noise_mg"], 50.0, 0.1, 20.0)
    assert fixed_slope_constant(taus, dev, -0.5) == pytest.approx(0.02, rel=TOLERANCE)
    assert np.array_equal(rec.columns["true_drift_mg"], np.zeros(len(rec)))


def test_switching_a_term_on_leaves_the_other_terms_unchanged() -> None:
    white = NoiseConfig("white_noise", {"n_mg_rt_s": 0.02})
    rrw = NoiseConfig("rate_random_walk", {"k_mg_per_rt_s": 1e-3})
    bi = NoiseConfig("bias_instability", {"b_mg": 0.01})
    only_white = simulate(_config((white,)), seed=5).columns
    only_rrw = simulate(_config((rrw,)), seed=5).columns
    only_bi = simulate(_config((bi,)), seed=5).columns
    everything = simulate(_config((white, bi, rrw)), seed=5).columns
    expected = only_white["true_noise_mg"] + only_bi["true_noise_mg"] + only_rrw["true_noise_mg"]
    np.testing.assert_allclose(everything["true_noise_mg"], expected, rtol=0, atol=1e-12)
    # the thermometer noise has its own stream too
    assert np.array_equal(everything["temp_c"], only_white["temp_c"])
    assert not np.array_equal(only_white["true_noise_mg"], only_rrw["true_noise_mg"])
