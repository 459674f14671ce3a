"""Building blocks of the mismatch finder, each against an independent expectation.

The noise covariance against the catalogue's Allan constants and Monte Carlo; the model columns
against the simulator's own ``true_drift_mg`` (a noise-free recording must be fitted exactly and
give back the catalogue parameters); the thermometer de-quantisation against the true die
temperature; the spectral and window scans against pure noise (no false alarms) and planted
signals; the profile's identifiability against what each protocol can physically show.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from trainer.data.recording import Recording
from trainer.diagnose.blocks import block_means, build_blocks, dequantize, detect_lattice
from trainer.diagnose.fit_summary import full_rate_model
from trainer.diagnose.gls import Gls, NoiseState, unit_matrices
from trainer.diagnose.locate import allan_comparison, scan_regions, spectral_peaks
from trainer.diagnose.model import Term, catalogue_effects, fit_model
from trainer.diagnose.profile import analyse_profile
from trainer.physics.config import (
    PhysicsConfig,
    ProtocolConfig,
    RecordingConfig,
    TemperatureConfig,
    load_config,
)
from trainer.physics.effects import EffectConfig
from trainer.physics.noise import noise_term
from trainer.physics.profiles import SegmentSpec
from trainer.physics.simulate import simulate

CYCLE = ProtocolConfig(
    "custom",
    -20.0,
    (
        SegmentSpec("soak", 1200.0, -20.0),
        SegmentSpec("ramp_up", 80.0 / 1.5 * 60.0, 60.0),
        SegmentSpec("hold", 1800.0, 60.0),
        SegmentSpec("ramp_down", 40.0 / 0.8 * 60.0, 20.0),
        SegmentSpec("hold", 1200.0, 20.0),
    ),
)
POLY = EffectConfig(
    "bias_poly", {"c0_mg": 0.3, "c1_mg_per_c": 0.15, "c2_mg_per_c2": 6e-4, "c3_mg_per_c3": -3e-6}
)


def _noise_free(effects: tuple[EffectConfig, ...], rate: float = 2.0) -> Recording:
    cfg = PhysicsConfig(
        recording=RecordingConfig(sample_rate_hz=rate),
        protocol=CYCLE,
        temperature=TemperatureConfig(case_tau_s=150.0, temp_noise_c=0.0),
        effects=(POLY, *effects),
    )
    return simulate(cfg, 1)


# ------------------------------------------------------------------------------------ noise model


def test_flicker_unit_covariance_has_the_catalogue_allan_floor() -> None:
    """AVAR at tau = B of block means with covariance F: (F00 - F01) must be (2 ln 2 / pi) b^2."""
    for block_s in (0.5, 7.0, 30.0):
        F = unit_matrices(50, block_s, 20000.0)["bias_instability"]
        avar = F[0, 0] - F[0, 1]
        assert avar == pytest.approx(2.0 * math.log(2.0) / math.pi, rel=0.03)


def test_random_walk_unit_covariance_matches_monte_carlo() -> None:
    """Empirical covariance of block means of simulated random walks (k = 1) against R."""
    rng = np.random.default_rng(5)
    m, nb, dt = 20, 6, 0.5
    walks = np.array(
        [noise_term("rate_random_walk", {"k_mg_per_rt_s": 1.0}, m * nb, dt, rng) for _ in range(4000)]
    )
    means = walks.reshape(4000, nb, m).mean(axis=2)
    R = unit_matrices(nb, m * dt, 1e4)["rate_random_walk"]
    empirical = np.cov(means, rowvar=False)
    assert np.allclose(empirical, R, rtol=0.12, atol=0.15 * R[0, 0] + 0.05)


def test_gls_with_white_noise_only_is_ordinary_least_squares() -> None:
    rng = np.random.default_rng(2)
    X = np.column_stack([np.ones(200), np.linspace(-1, 1, 200)])
    y = X @ np.array([1.0, -2.0]) + rng.standard_normal(200) * 0.3
    result = Gls(200, 1.0, 200.0, NoiseState((), ())).fit(X, y)
    beta_ols, rss_ols, *_ = np.linalg.lstsq(X, y, rcond=None)
    assert np.allclose(result.beta, beta_ols)
    s2 = float(rss_ols[0]) / 200
    assert result.loglik == pytest.approx(-100.0 * (math.log(2 * math.pi * s2) + 1.0))


def test_correlated_gls_is_the_generalised_least_squares_of_its_covariance() -> None:
    """With flicker and a random walk: the factor is lower triangular and rebuilds ``I + a F + b R``;
    beta, the likelihood and the restricted likelihood are those of the dense formulas, whichever
    data vector the same factor fitted before (it keeps the last one whitened)."""
    n, block_s, duration_s = 80, 5.0, 400.0
    state = NoiseState(("bias_instability", "rate_random_walk"), (0.5, -1.0))
    units = unit_matrices(n, block_s, duration_s)
    cov = np.eye(n) + 10**0.5 * units["bias_instability"] + 10**-1.0 * units["rate_random_walk"]
    gls = Gls(n, block_s, duration_s, state)
    assert np.array_equal(np.triu(gls.chol, 1), np.zeros((n, n)))
    assert np.allclose(gls.chol @ gls.chol.T, cov, rtol=1e-12, atol=1e-12)
    assert np.allclose(gls.cov_unit, cov, rtol=1e-15, atol=0.0)
    rng = np.random.default_rng(3)
    X = np.column_stack([np.ones(n), np.linspace(-1, 1, n)])
    inverse = np.linalg.inv(cov)
    for y in (rng.standard_normal(n), rng.standard_normal(n) + 3.0):
        beta = np.linalg.solve(X.T @ inverse @ X, X.T @ inverse @ y)
        r = y - X @ beta
        rss = float(r @ inverse @ r)
        _, logdet = np.linalg.slogdet(cov)
        loglik = -0.5 * n * (math.log(2 * math.pi * rss / n) + 1.0) - 0.5 * logdet
        _, logdet_xtx = np.linalg.slogdet(X.T @ inverse @ X)
        dof = n - 2
        reml = -0.5 * dof * (math.log(2 * math.pi * rss / dof) + 1.0) - 0.5 * logdet - 0.5 * logdet_xtx
        for _ in range(2):  # the second fit reads the cached whitened y
            result = gls.fit(X, y, reml=True)
            assert np.allclose(result.beta, beta, rtol=1e-9)
            assert result.loglik == pytest.approx(loglik, rel=1e-10)
            assert result.reml == pytest.approx(reml, rel=1e-10)
        assert math.isnan(gls.fit(X, y).reml)  # the QR only when asked for


# ------------------------------------------------------------------------------------ model


@pytest.mark.parametrize(
    "effect",
    [
        EffectConfig("thermal_lag", {"tau_s": 240.0}),
        EffectConfig("temp_rate", {"k_mg_per_c_per_min": -0.3}),
        EffectConfig("hysteresis", {"amp_mg": 0.2, "width_c": 4.0}),
        EffectConfig("stress_relaxation", {"gain_mg_per_c": 0.02, "tau_s": 2500.0}),
        EffectConfig("warmup", {"amp_mg": 0.8, "tau_s": 400.0}),
        EffectConfig("periodic", {"amp_mg": 0.05, "period_s": 700.0, "phase_rad": 1.0}),
        EffectConfig("bias_step", {"t_s": 5000.0, "step_mg": -0.3}),
    ],
    ids=lambda e: e.identifier,
)
def test_noise_free_drift_gives_back_the_catalogue_parameters(effect: EffectConfig) -> None:
    """Fitting the right terms to the simulator's drift recovers its parameters and reproduces it."""
    rec = _noise_free((effect,))
    truth = rec.columns["true_drift_mg"]
    rec.columns["accel_mg"] = truth.copy()
    data = build_blocks(rec.without_truth())
    start = {"thermal_lag": 60.0, "hysteresis": 10.0, "stress_relaxation": 1500.0, "warmup": 150.0}
    nl: tuple[float, ...] = ()
    if effect.identifier in start:
        nl = (start[effect.identifier],)
    elif effect.identifier == "periodic":
        nl = (690.0,)
    elif effect.identifier == "bias_step":
        nl = (4980.0,)
    fit = fit_model((Term("bias_poly"), Term(effect.identifier, nl)), (), data)
    found = {e.identifier: e.params for e in catalogue_effects(fit)}
    for name, value in effect.params.items():
        assert found[effect.identifier][name] == pytest.approx(
            value, rel=0.02, abs=0.02 if "phase" in name else 1e-6
        )
    for name, value in POLY.params.items():
        assert found["bias_poly"][name] == pytest.approx(
            value, rel=0.05, abs=2e-3 if name == "c0_mg" else 1e-7
        )
    rerun = full_rate_model(fit)  # the augmented simulation rerun through physics.effects.drift
    assert np.sqrt(np.mean((rerun - truth) ** 2)) < 0.01 * np.ptp(truth) + 1e-3


# ------------------------------------------------------------------------------------ thermometer


def test_lattice_detection() -> None:
    rng = np.random.default_rng(0)
    smooth = np.linspace(-10, 30, 5000) + rng.standard_normal(5000) * 0.02
    assert detect_lattice(smooth) is None
    for lsb in (0.0625, 0.25, 1.0):
        assert detect_lattice(lsb * np.round(smooth / lsb)) == pytest.approx(lsb)


def test_dequantised_temperature_tracks_the_die_far_better_than_the_staircase() -> None:
    cfg = PhysicsConfig(
        recording=RecordingConfig(sample_rate_hz=5.0),
        protocol=CYCLE,
        temperature=TemperatureConfig(case_tau_s=150.0, temp_noise_c=0.01),
        effects=(POLY, EffectConfig("temp_quantization", {"lsb_c": 0.5})),
    )
    rec = simulate(cfg, 3)
    t = rec.time_s
    knots_t, knots_v, plateaus = dequantize(t, rec.temp_c, 0.5)
    true = rec.columns["true_temp_c"]
    inside = np.zeros(t.size, bool)
    for a, b in plateaus:
        inside |= (t >= a) & (t < b)
    smooth = np.interp(t, knots_t, knots_v)
    staircase_err = np.sqrt(np.mean((rec.temp_c - true)[~inside] ** 2))
    smooth_err = np.sqrt(np.mean((smooth - true)[~inside] ** 2))
    assert staircase_err > 0.1  # about lsb / sqrt(12) = 0.14
    assert smooth_err < 0.35 * staircase_err
    assert plateaus  # the holds are flagged as known only within one LSB


# ------------------------------------------------------------------------------------ locate


@pytest.mark.parametrize("seed", range(4))
def test_spectral_scan_stays_quiet_on_coloured_noise(seed: int) -> None:
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(20000) * 0.1 + noise_term("bias_instability", {"b_mg": 0.03}, 20000, 0.5, rng)
    assert spectral_peaks(x, 0.5, 4.0, 2000.0) == []


def test_spectral_scan_finds_a_sub_noise_tone() -> None:
    rng = np.random.default_rng(9)
    t = np.arange(20000) * 0.5
    x = rng.standard_normal(t.size) * 0.2 + 0.02 * np.sin(2 * np.pi * t / 37.0)  # 10 x below the noise
    peaks = spectral_peaks(x, 0.5, 4.0, 2000.0)
    assert peaks and peaks[0].period_s == pytest.approx(37.0, rel=0.01) and peaks[0].p_value < 1e-6


def _white_blocks(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.standard_normal(n) * 0.01, np.eye(n) * 1e-4


def test_window_scan_flags_a_planted_offset_and_nothing_in_noise() -> None:
    rec = _noise_free(())
    data = build_blocks(rec.without_truth(), max_blocks=300)
    profile = analyse_profile(data, rec.meta)
    for seed in range(3):
        residual, cov = _white_blocks(data.n, seed)
        assert scan_regions(residual, cov, data, profile) == []
    residual, cov = _white_blocks(data.n, 7)
    residual[100:140] += 0.02  # 2 sigma per block, hard to see by eye, 12 sigma over the 40 blocks
    regions = scan_regions(residual, cov, data, profile)
    assert len(regions) == 1
    assert regions[0].t_start_s <= data.t[105] and regions[0].t_end_s >= data.t[135]


def test_allan_comparison_accepts_the_true_noise_model() -> None:
    rng = np.random.default_rng(4)
    x = noise_term("white_noise", {"n_mg_rt_s": 0.05}, 400000, 0.01, rng)
    x += noise_term("bias_instability", {"b_mg": 0.01}, 400000, 0.01, rng)
    model = {"white_noise": {"n_mg_rt_s": 0.05}, "bias_instability": {"b_mg": 0.01}}
    assert allan_comparison(x, 100.0, 4000.0, model).departures == []
    too_small = {"white_noise": {"n_mg_rt_s": 0.05}}  # flicker floor left out of the model
    (tau_min, _, ratio), *_ = allan_comparison(x, 100.0, 4000.0, too_small).departures
    assert tau_min > 20.0 and ratio > 2.0  # where flicker overtakes 0.05 / sqrt(tau): tau > 56 s


# ------------------------------------------------------------------------------------ profile


def test_identifiability_follows_the_protocol() -> None:
    cfg = replace(load_config(None), recording=RecordingConfig(sample_rate_hz=1.0))
    single = simulate(cfg, 1)  # paper-oven: one 1 degC/min ramp
    p1 = analyse_profile(build_blocks(single.without_truth()), single.meta).identifiability
    assert not p1["hysteresis"].identifiable and "ramp_down" in p1["hysteresis"].test
    assert not p1["stress_relaxation"].identifiable
    assert not p1["scale_factor_tc"].identifiable and "180" in p1["scale_factor_tc"].test
    assert p1["thermal_lag"].weak  # only the start of the ramp separates lag from dT/dt
    cycle = _noise_free(())
    p2 = analyse_profile(build_blocks(cycle.without_truth()), cycle.meta)
    assert p2.reversals == 1 and len(p2.ramp_rates) == 2
    for effect in ("hysteresis", "thermal_lag", "temp_rate"):
        assert p2.identifiability[effect].identifiable and not p2.identifiability[effect].weak
    assert p2.identifiability["stress_relaxation"].identifiable  # weak: the hold is shorter than 1 h
    assert [s.label for s in p2.segments] == ["soak", "ramp_up", "hold", "ramp_down", "hold"]


def test_branches_and_segments_without_metadata() -> None:
    rec = _noise_free(())
    rec.meta.pop("segments")
    data = build_blocks(rec.without_truth())
    profile = analyse_profile(data, rec.meta)
    assert profile.segments_from == "temperature"
    labels = [s.label for s in profile.segments]
    assert labels[:2] == ["soak", "ramp_up"] and "ramp_down" in labels
    t_mid_ramp = 1200.0 + 1600.0
    k = int(np.searchsorted(data.t, t_mid_ramp))
    assert profile.branch[k] == 1
    k = int(np.searchsorted(data.t, 1200.0 + 3200.0 + 1800.0 + 1500.0))
    assert profile.branch[k] == -1
    means = block_means(rec.temp_c, data.samples_per_block, data.n)
    assert np.allclose(means, data.temp)
