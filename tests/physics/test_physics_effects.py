"""Each effect alone against its formula written out here, plus the simulator's invariants.

Expectations are independent: closed-form responses of first-order low-passes to a ramp, a
plain-loop play operator, least-squares sinusoid fits. Short custom protocols keep it fast.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trainer.data.recording import Recording
from trainer.physics.config import parse_config_text
from trainer.physics.effects import effect_contribution
from trainer.physics.profiles import parse_segments
from trainer.physics.simulate import simulate
from trainer.physics.thermal import lowpass, play_operator

T_REF = 25.0
RATE_C_PER_S = 1.0 / 60.0
RAMP = """
[[protocol.segments]]
label = "ramp_up"
rate_c_per_min = 1.0
end_c = 80.0
"""
# heat 0 -> 60 at 1 degC/min, hold 10 min, cool back to 0: both hysteresis branches over 0..60
LOOP = """
[[protocol.segments]]
label = "ramp_up"
rate_c_per_min = 1.0
end_c = 60.0
[[protocol.segments]]
label = "hold"
duration_s = 600.0
[[protocol.segments]]
label = "ramp_down"
rate_c_per_min = 1.0
end_c = 0.0
"""


def run(
    body: str = "",
    *,
    segments: str = RAMP,
    start_c: float = -40.0,
    fs: float = 10.0,
    case_tau_s: float = 100.0,
    temp_noise_c: float = 0.0,
    seed: int = 1,
) -> Recording:
    text = f"""
[recording]
sample_rate_hz = {fs}
[protocol]
name = "custom"
start_c = {start_c}
{segments}
[temperature]
case_tau_s = {case_tau_s}
temp_noise_c = {temp_noise_c}
{body}
"""
    return simulate(parse_config_text(text, "test.toml"), seed)


def lp_of_ramp(t: np.ndarray, x0: float, r: float, tau: float) -> np.ndarray:
    """dy/dt = (x0 + r t - y)/tau, y(0) = x0."""
    return x0 + r * t - r * tau * (1.0 - np.exp(-t / tau))


def lp_of_lp_of_ramp(t: np.ndarray, x0: float, r: float, tau1: float, tau2: float) -> np.ndarray:
    """Two cascaded low-passes (tau1 then tau2) of a ramp, both started in equilibrium."""
    e1, e2 = np.exp(-t / tau1), np.exp(-t / tau2)
    return x0 + r * t - r * (tau1 + tau2) * (1.0 - e2) + r * tau1**2 / (tau1 - tau2) * (e1 - e2)


def reference_play(x: np.ndarray, width: float) -> np.ndarray:
    p = float(x[0])
    out = []
    for value in x.tolist():
        p = min(max(p, value - width / 2), value + width / 2)
        out.append(p)
    return np.array(out)


# ------------------------------------------------------------------------ temperature chain


def test_die_temperature_is_the_lowpass_of_the_ramp_exactly() -> None:
    rec = run(case_tau_s=180.0)
    t = rec.time_s
    np.testing.assert_allclose(rec.columns["chamber_c"], -40.0 + RATE_C_PER_S * t, atol=1e-9)
    np.testing.assert_allclose(
        rec.columns["true_temp_c"], lp_of_ramp(t, -40.0, RATE_C_PER_S, 180.0), atol=1e-9
    )
    assert np.array_equal(rec.temp_c, rec.columns["true_temp_c"])  # no thermometer noise here
    assert np.array_equal(rec.columns["true_pm_temp_c"], rec.columns["true_temp_c"])  # no thermal_lag


def test_thermal_lag_proof_mass_follows_two_cascaded_lowpasses() -> None:
    body = "[effects.thermal_lag]\ntau_s = 300.0\n[effects.bias_poly]\nc1_mg_per_c = 0.1"
    rec = run(body, case_tau_s=100.0)
    t = rec.time_s
    expected_pm = lp_of_lp_of_ramp(t, -40.0, RATE_C_PER_S, 100.0, 300.0)
    np.testing.assert_allclose(rec.columns["true_pm_temp_c"], expected_pm, atol=1e-8)
    # the bias reads the proof mass, not the thermometer: late in the ramp it lags by r (tau1 + tau2)
    np.testing.assert_allclose(rec.columns["true_drift_mg"], 0.1 * (expected_pm - T_REF), atol=1e-9)
    late = t > 3000
    lag = rec.columns["true_temp_c"][late] - rec.columns["true_pm_temp_c"][late]
    np.testing.assert_allclose(lag, RATE_C_PER_S * 300.0, rtol=1e-3)


def test_bias_poly_alone() -> None:
    body = """[effects.bias_poly]
c0_mg = 0.4
c1_mg_per_c = 0.12
c2_mg_per_c2 = -8e-4
c3_mg_per_c3 = 5e-6"""
    rec = run(body)
    dT = rec.columns["true_temp_c"] - T_REF
    expected = 0.4 + 0.12 * dT - 8e-4 * dT**2 + 5e-6 * dT**3
    np.testing.assert_allclose(rec.columns["true_drift_mg"], expected, atol=1e-12)


def test_temp_rate_is_k_times_die_rate_in_c_per_min() -> None:
    rec = run("[effects.temp_rate]\nk_mg_per_c_per_min = 0.5", case_tau_s=120.0)
    rate_per_min = 60.0 * RATE_C_PER_S * (1.0 - np.exp(-rec.time_s / 120.0))  # d/dt of the LP of a ramp
    np.testing.assert_allclose(rec.columns["true_drift_mg"], 0.5 * rate_per_min, atol=1e-9)


def test_stress_relaxation_on_a_ramp() -> None:
    rec = run("[effects.stress_relaxation]\ngain_mg_per_c = 0.02\ntau_s = 1500.0", case_tau_s=100.0)
    t = rec.time_s
    die = lp_of_ramp(t, -40.0, RATE_C_PER_S, 100.0)
    relaxed = lp_of_lp_of_ramp(t, -40.0, RATE_C_PER_S, 100.0, 1500.0)
    np.testing.assert_allclose(rec.columns["true_drift_mg"], 0.02 * (die - relaxed), atol=1e-9)


def test_stress_relaxation_step_response_decays_with_tau() -> None:
    t = np.arange(20_000) * 1.0
    step_at, jump, gain, tau = 1000, 10.0, 0.03, 1200.0
    T_die = np.where(np.arange(t.size) >= step_at, 20.0 + jump, 20.0)
    out = effect_contribution("stress_relaxation", {"gain_mg_per_c": gain, "tau_s": tau}, t, T_die, T_die)
    assert np.all(out[:step_at] == 0.0)
    after = t[step_at:] - t[step_at]
    # package creep: the step appears in full, then relaxes exponentially (one-sample ramp: <1e-3)
    np.testing.assert_allclose(out[step_at:], gain * jump * np.exp(-after / tau), atol=1e-3 * gain * jump)


# ------------------------------------------------------------------------------- hysteresis


@settings(max_examples=60, deadline=None)
@given(
    steps=st.lists(st.floats(-3.0, 3.0), min_size=1, max_size=3000),
    width=st.floats(0.0, 8.0),
    noise_scale=st.sampled_from([0.0, 0.1, 5.0]),
)
def test_play_operator_matches_its_recursion(steps: list[float], width: float, noise_scale: float) -> None:
    x = np.cumsum(steps) + noise_scale * np.sin(np.arange(len(steps)) * 1.7)
    assert np.array_equal(play_operator(x, width), reference_play(x, width))


def test_play_operator_with_many_reversals_on_a_long_input() -> None:
    x = np.random.default_rng(3).normal(size=50_000)  # reverses almost every sample
    assert np.array_equal(play_operator(x, 0.5), reference_play(x, 0.5))


def test_hysteresis_branches_differ_by_two_amp_and_persist_in_the_hold() -> None:
    amp, width = 0.4, 10.0
    rec = run(
        f"[effects.hysteresis]\namp_mg = {amp}\nwidth_c = {width}", segments=LOOP, start_c=0.0, case_tau_s=5.0
    )
    T = rec.columns["true_pm_temp_c"]
    drift = rec.columns["true_drift_mg"]
    peak = int(np.argmax(T))
    heating = (np.arange(T.size) < peak) & (T > 15) & (T < 45)
    cooling = (np.arange(T.size) > peak) & (T > 15) & (T < 45)
    np.testing.assert_allclose(drift[heating], amp, atol=1e-9)
    np.testing.assert_allclose(drift[cooling], -amp, atol=1e-9)
    # at the same temperature the two branches differ by 2 amp
    probe = np.array([20.0, 30.0, 40.0])
    up = np.interp(probe, T[heating], drift[heating])
    order = np.argsort(T[cooling])
    down = np.interp(probe, T[cooling][order], drift[cooling][order])
    np.testing.assert_allclose(up - down, 2 * amp, atol=1e-9)
    # the hold at 60 degC keeps the heating-branch offset
    segments = dict((label, (a, b)) for label, a, b in parse_segments(rec.meta["segments"]))
    hold = (rec.time_s >= segments["hold"][0]) & (rec.time_s < segments["hold"][1])
    np.testing.assert_allclose(drift[hold], amp, atol=1e-9)


def test_bias_poly_reads_the_play_output_when_hysteresis_is_present() -> None:
    amp, width = 0.3, 6.0
    body = f"[effects.hysteresis]\namp_mg = {amp}\nwidth_c = {width}\n"
    body += "[effects.bias_poly]\nc1_mg_per_c = 0.1\nc2_mg_per_c2 = 1e-3"
    rec = run(body, segments=LOOP, start_c=0.0, case_tau_s=50.0, fs=2.0)
    T = rec.columns["true_pm_temp_c"]
    P = reference_play(T, width)
    expected = 0.1 * (P - T_REF) + 1e-3 * (P - T_REF) ** 2 + amp * (T - P) / (width / 2)
    np.testing.assert_allclose(rec.columns["true_drift_mg"], expected, atol=1e-9)


# -------------------------------------------------------------------------- time-only effects


def test_warmup_amplitude_at_zero_and_at_tau() -> None:
    rec = run("[effects.warmup]\namp_mg = 2.0\ntau_s = 300.0")
    drift, t = rec.columns["true_drift_mg"], rec.time_s
    assert drift[0] == pytest.approx(2.0)
    assert drift[np.searchsorted(t, 300.0)] == pytest.approx(2.0 / math.e)
    assert drift[-1] == pytest.approx(2.0 * math.exp(-t[-1] / 300.0))


def test_bias_steps_add_up_and_switch_at_t_s() -> None:
    body = "[[effects.bias_step]]\nt_s = 1000.0\nstep_mg = 0.5\n"
    body += "[[effects.bias_step]]\nt_s = 4000.0\nstep_mg = -2.0"
    rec = run(body)
    t, drift = rec.time_s, rec.columns["true_drift_mg"]
    expected = np.select([t < 1000.0, t < 4000.0], [0.0, 0.5], default=-1.5)
    assert np.array_equal(drift, expected)
    assert drift[np.searchsorted(t, 1000.0)] == 0.5  # H(0) = 1: the step is in the sample at t_s


def test_periodic_amplitude_period_and_phase() -> None:
    body = """[[effects.periodic]]
amp_mg = 0.3
period_s = 100.0
phase_rad = 0.7
[[effects.periodic]]
amp_mg = 0.05
period_s = 720.0"""
    rec = run(body)
    t, drift = rec.time_s, rec.columns["true_drift_mg"]
    spectrum = np.abs(np.fft.rfft(drift))
    freqs = np.fft.rfftfreq(t.size, d=t[1] - t[0])
    top_two = freqs[np.argsort(spectrum)[-2:]]
    assert sorted(1.0 / top_two) == pytest.approx([100.0, 720.0])
    columns = []
    for period in (100.0, 720.0):
        w = 2 * np.pi / period
        columns += [np.sin(w * t), np.cos(w * t)]
    coef = np.linalg.lstsq(np.column_stack(columns), drift, rcond=None)[0]
    assert math.hypot(coef[0], coef[1]) == pytest.approx(0.3)
    assert math.atan2(coef[1], coef[0]) == pytest.approx(0.7)
    assert math.hypot(coef[2], coef[3]) == pytest.approx(0.05)
    assert math.atan2(coef[3], coef[2]) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("lsb", [0.0625, 0.25, 1.0])
def test_temp_quantization_gives_a_staircase_of_lsb_multiples(lsb: float) -> None:
    rec = run(f"[effects.temp_quantization]\nlsb_c = {lsb}")
    temp, truth = rec.temp_c, rec.columns["true_temp_c"]
    assert np.array_equal(temp / lsb, np.round(temp / lsb))
    assert np.all(np.abs(temp - truth) <= lsb / 2 + 1e-12)
    assert set(np.unique(np.diff(temp))) <= {0.0, lsb}  # a rising staircase, one lsb at a time
    assert np.array_equal(rec.columns["true_drift_mg"], np.zeros(len(rec)))  # bias unaffected


def test_scale_factor_tc_is_invisible_without_input() -> None:
    rec = run("[effects.scale_factor_tc]\nsf_ppm_per_c = 150.0")
    assert np.array_equal(rec.columns["true_drift_mg"], np.zeros(len(rec)))


@pytest.mark.parametrize(
    "body",
    [
        "[input]\nkind = 'constant'\nvalue_mg = 1000.0\n[effects.scale_factor_tc]\nsf_ppm_per_c = 150.0",
        "[effects.scale_factor_tc]\nsf_ppm_per_c = 150.0\ng_in_mg = 1000.0",
    ],
)
def test_scale_factor_tc_with_a_constant_input(body: str) -> None:
    rec = run(body)
    T_pm = rec.columns["true_pm_temp_c"]
    np.testing.assert_allclose(rec.columns["true_drift_mg"], 1000.0 * 150e-6 * (T_pm - T_REF), atol=1e-12)
    assert np.all(rec.columns["true_accel_mg"] == 1000.0)
    np.testing.assert_allclose(rec.accel_mg, 1000.0 * (1 + 150e-6 * (T_pm - T_REF)), atol=1e-12)


# ---------------------------------------------------------------------------------- inputs


def test_step_input() -> None:
    rec = run("[input]\nkind = 'steps'\nsteps = [[100.0, 1000.0], [200.0, -1000.0]]", fs=1.0)
    t, g = rec.time_s, rec.columns["true_accel_mg"]
    assert np.array_equal(g, np.select([t < 100, t < 200], [0.0, 1000.0], default=-1000.0))


def test_motion_input_tones_and_singer_manoeuvre() -> None:
    body = """[input]
kind = "motion"
offset_mg = 20.0
singer_sigma_mg = 30.0
singer_tau_s = 5.0
[[input.tones]]
amp_mg = 50.0
freq_hz = 0.5
phase_rad = 0.3"""
    rec = run(body)
    t, g = rec.time_s, rec.columns["true_accel_mg"]
    tone = 50.0 * np.sin(2 * np.pi * 0.5 * t + 0.3)
    manoeuvre = g - 20.0 - tone
    # Singer model: stationary Gauss-Markov, RMS sigma, correlation exp(-lag/tau)
    assert np.std(manoeuvre) == pytest.approx(30.0, rel=0.1)
    lag = 50  # 5 s at 10 Hz
    corr = np.corrcoef(manoeuvre[:-lag], manoeuvre[lag:])[0, 1]
    assert corr == pytest.approx(math.exp(-1.0), abs=0.05)
    assert np.mean(manoeuvre) == pytest.approx(0.0, abs=5.0)


# ------------------------------------------------------------------------------ invariants

EVERYTHING = """
[input]
kind = "motion"
offset_mg = 5.0
singer_sigma_mg = 2.0
singer_tau_s = 10.0
[[input.tones]]
amp_mg = 1.0
freq_hz = 0.2
[effects.bias_poly]
c1_mg_per_c = 0.1
c2_mg_per_c2 = 1e-3
[effects.thermal_lag]
tau_s = 60.0
[effects.temp_rate]
k_mg_per_c_per_min = 0.2
[effects.hysteresis]
amp_mg = 0.1
width_c = 5.0
[effects.stress_relaxation]
gain_mg_per_c = 0.01
tau_s = 2000.0
[effects.warmup]
amp_mg = 1.0
tau_s = 200.0
[effects.periodic]
amp_mg = 0.05
period_s = 300.0
[effects.bias_step]
t_s = 500.0
step_mg = 0.2
[effects.temp_quantization]
lsb_c = 0.0625
[effects.scale_factor_tc]
sf_ppm_per_c = 100.0
[noise.quantization_noise]
q_mg = 0.001
[noise.white_noise]
n_mg_rt_s = 0.02
[noise.bias_instability]
b_mg = 0.01
[noise.rate_random_walk]
k_mg_per_rt_s = 1e-4
[noise.rate_ramp]
r_mg_per_s = 1e-6
"""


def test_output_is_truth_plus_drift_plus_noise() -> None:
    rec = run(EVERYTHING, temp_noise_c=0.05)
    c = rec.columns
    np.testing.assert_allclose(
        c["accel_mg"], c["true_accel_mg"] + c["true_drift_mg"] + c["true_noise_mg"], atol=1e-12
    )
    assert np.std(c["true_noise_mg"]) > 0 and np.ptp(c["true_drift_mg"]) > 1.0
    assert list(c)[:3] == ["time_s", "temp_c", "accel_mg"]
    assert {"chamber_c", "true_temp_c", "true_pm_temp_c"} <= set(c)


def test_same_seed_same_recording_different_seed_different_noise() -> None:
    a, b, other = (
        run(EVERYTHING, temp_noise_c=0.05),
        run(EVERYTHING, temp_noise_c=0.05),
        run(EVERYTHING, temp_noise_c=0.05, seed=2),
    )
    for name in a.columns:
        assert np.array_equal(a.columns[name], b.columns[name]), name
    assert a.meta == b.meta
    for name in ("accel_mg", "temp_c", "true_noise_mg", "true_accel_mg"):
        assert not np.array_equal(a.columns[name], other.columns[name]), name
    for name in ("true_temp_c", "chamber_c", "time_s"):  # deterministic chain
        assert np.array_equal(a.columns[name], other.columns[name]), name


def test_noise_terms_do_not_change_input_or_thermometer_streams() -> None:
    with_noise = run(EVERYTHING, temp_noise_c=0.05)
    quiet = run(EVERYTHING.split("[noise.quantization_noise]")[0], temp_noise_c=0.05)
    for name in ("temp_c", "true_accel_mg", "true_drift_mg"):
        assert np.array_equal(with_noise.columns[name], quiet.columns[name]), name
    assert np.array_equal(quiet.columns["true_noise_mg"], np.zeros(len(quiet)))


def test_lowpass_keeps_a_constant_and_starts_in_equilibrium() -> None:
    assert np.array_equal(lowpass(np.full(1000, 37.5), 20000.0, 0.005), np.full(1000, 37.5))
    assert lowpass(np.array([3.0, 10.0]), 1.0, 1.0)[0] == 3.0
