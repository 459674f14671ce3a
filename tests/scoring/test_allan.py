"""Tests of trainer.scoring.allan against noise synthesised here with known IEEE 952 coefficients.

The generators below are this file's own (not the project's simulator). Derivations, for a rate
signal x (mg) sampled at fs with period dt = 1/fs:

* white, density n (mg s^1/2): averaging m samples of variance s^2 gives s^2/m = s^2 dt/tau, and
  for white noise AVAR(tau) is that variance, so sigma = n/sqrt(tau) needs s = n sqrt(fs).
* rate random walk, k (mg/s^1/2): x = k W(t) with W a Wiener process has AVAR = k^2 tau/3; its
  discrete steps have standard deviation k sqrt(dt).
* rate ramp, r (mg/s): x = r t; consecutive tau-averages differ by r tau, AVAR = (r tau)^2/2.
* quantization, q (mg): allantools integrates x to phase y = sum(x) dt. If y carries white
  error e of variance q^2, AVAR = E[(e2 - 2e1 + e0)^2] / (2 tau^2) = 3 q^2/tau^2, i.e.
  sigma = sqrt(3) q/tau. So x = fs * diff(e), e ~ N(0, q^2).
* bias instability, B (mg): a sum of first-order Gauss-Markov processes, equal variance s^2,
  time constants log-spaced with ratio rho, has two-sided PSD sum 2 s^2 Tc / (1 + (2 pi f Tc)^2)
  ~ integral over ln Tc / ln rho = s^2 / (2 ln(rho) f). A two-sided 1/f PSD h/f has
  AVAR = 4 ln2 h; IEEE 952 writes the floor as (2 ln2/pi) B^2, so s = B sqrt(ln(rho)/pi).
"""

from __future__ import annotations

import math
import time
from functools import cache

import numpy as np
import pytest
from scipy.signal import lfilter

from trainer.scoring.allan import (
    BIAS_INSTABILITY_FACTOR,
    AllanCurve,
    allan_deviation,
    allan_table,
    default_taus,
    improvement_percent,
    local_slopes,
    noise_coefficients,
    plot_allan,
)

TERMS = ("q_mg", "n_mg_rt_s", "b_mg", "k_mg_per_rt_s", "r_mg_per_s")

# ---------------------------------------------------------------------------------------------
# independent generators
# ---------------------------------------------------------------------------------------------


def white(rng: np.random.Generator, n: float, fs: float, size: int) -> np.ndarray:
    return rng.normal(0.0, n * math.sqrt(fs), size)


def rate_random_walk(rng: np.random.Generator, k: float, fs: float, size: int) -> np.ndarray:
    return np.cumsum(rng.normal(0.0, k / math.sqrt(fs), size))


def rate_ramp(r: float, fs: float, size: int) -> np.ndarray:
    return r * np.arange(size) / fs


def quantization(rng: np.random.Generator, q: float, fs: float, size: int) -> np.ndarray:
    return fs * np.diff(rng.normal(0.0, q, size + 1))


def flicker(
    rng: np.random.Generator,
    b: float,
    fs: float,
    size: int,
    tc_range_s: tuple[float, float] = (0.02, 1e5),
    per_decade: int = 3,
) -> np.ndarray:
    """Sum of stationary Gauss-Markov processes with log-spaced time constants (1/f over the range)."""
    decades = math.log10(tc_range_s[1] / tc_range_s[0])
    time_constants = np.logspace(*np.log10(tc_range_s), round(per_decade * decades) + 1)
    s = b * math.sqrt(math.log(10.0 ** (1.0 / per_decade)) / math.pi)
    out = np.zeros(size)
    for tc in time_constants:
        a = math.exp(-1.0 / (fs * tc))
        drive = rng.normal(0.0, s * math.sqrt(1.0 - a * a), size)
        start = rng.normal(0.0, s)  # start in the stationary distribution
        out += lfilter([1.0], [1.0, -a], drive, zi=[a * start])[0]
    return out


# ---------------------------------------------------------------------------------------------
# cached cases (each signal and curve is built once per session)
# ---------------------------------------------------------------------------------------------

SEED = 20240611  # fixed for reproducibility; the checks were also run with seeds 0-29
FS = 10.0
COMBO_N, COMBO_K = 0.05, math.sqrt(3.0) * 0.05 / 3.0  # white -> RRW crossover at 3 s
COMBO_R = math.sqrt(2.0 * COMBO_K**2 / (3.0 * 100.0))  # RRW -> ramp crossover at 100 s

SINGLE_CASES: dict[str, tuple[str, float]] = {
    "white": ("n_mg_rt_s", 0.05),
    "quantization": ("q_mg", 0.01),
    "rrw": ("k_mg_per_rt_s", 0.002),
    "ramp": ("r_mg_per_s", 2e-5),
    "flicker": ("b_mg", 0.02),
}


@cache
def signal(case: str) -> np.ndarray:
    rng = np.random.default_rng(SEED)
    truth = SINGLE_CASES[case][1] if case in SINGLE_CASES else math.nan
    if case == "white":
        return white(rng, truth, FS, 200_000)
    if case == "quantization":
        return quantization(rng, truth, FS, 200_000)
    if case == "rrw":
        return rate_random_walk(rng, truth, FS, 200_000)
    if case == "ramp":
        return rate_ramp(truth, FS, 200_000)
    if case == "flicker":
        return flicker(rng, truth, FS, 1_000_000)
    if case == "combo":
        size = 1_000_000
        return (
            white(rng, COMBO_N, FS, size)
            + rate_random_walk(rng, COMBO_K, FS, size)
            + rate_ramp(COMBO_R, FS, size)
        )
    if case == "bowl":
        size = 400_000
        return white(rng, 0.05, FS, size) + rate_random_walk(rng, 0.01, FS, size)  # bottom ~9 s
    raise KeyError(case)


@cache
def curve(case: str) -> AllanCurve:
    return allan_deviation(signal(case), FS)


# ---------------------------------------------------------------------------------------------
# the Allan deviation itself
# ---------------------------------------------------------------------------------------------


def test_default_grid_is_log_spaced_from_one_sample_to_a_tenth_of_the_record() -> None:
    taus = default_taus(1_440_000, 200.0)
    assert taus[0] == pytest.approx(1 / 200.0)
    assert taus[-1] <= 1_440_000 / (10 * 200.0) + 1e-9
    assert taus[-1] >= 0.9 * 1_440_000 / (10 * 200.0)
    per_decade = len(taus) / math.log10(taus[-1] / taus[0])
    assert 8 <= per_decade <= 11  # ~10 per decade, fewer where whole-sample rounding merges taus
    assert np.all(np.diff(taus) > 0)
    assert np.allclose(taus * 200.0, np.round(taus * 200.0))


def test_tau_keywords_follow_allantools_definitions() -> None:
    assert np.allclose(default_taus(1000, 1.0, "octave"), [1, 2, 4, 8, 16, 32, 64])
    assert np.allclose(default_taus(1000, 1.0, "decade"), [1, 2, 4, 10, 20, 40, 100])
    assert len(default_taus(100_000, 1.0, 5)) == 21  # 4 decades at 5 per decade, both ends
    explicit = default_taus(1000, 10.0, [0.1, 0.25, 5.0, 50.0])  # 50 s is past the N/10 cap
    assert np.allclose(explicit, [0.1, 0.2, 5.0])  # 0.25 s rounds to 2 samples (round half even)
    assert np.allclose(default_taus(1000, 1.0, [400.0], max_tau_s=400.0), [400.0])
    with pytest.raises(ValueError):
        default_taus(1000, 1.0, True)
    with pytest.raises(ValueError):
        default_taus(1000, 1.0, "all")


def test_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="non-finite"):
        allan_deviation(np.array([1.0, np.nan, 2.0, 3.0]), 1.0)
    with pytest.raises(ValueError, match="1-D"):
        allan_deviation(np.zeros((10, 2)), 1.0)
    with pytest.raises(ValueError, match="rate_hz"):
        allan_deviation(np.zeros(100), 0.0)


def test_white_noise_adev_follows_n_over_sqrt_tau_within_its_error_bars() -> None:
    n = 0.05
    result = curve("white")
    chi = (result.adev - n / np.sqrt(result.taus_s)) / result.adev_err
    # Neighbouring taus share data and move together, so one excursion spans several points;
    # 4 error bars bounds it (seen up to 3.3 over 17 seeds), the RMS checks the bars' scale.
    assert np.max(np.abs(chi)) <= 4.0
    # Error bars honest both ways: not so wide that every point sits deep inside them.
    assert 0.3 <= math.sqrt(float(np.mean(chi**2))) <= 1.5
    assert result.n_pairs[0] == len(signal("white")) - 1  # N+1 phase points, second differences
    slopes = local_slopes(result.taus_s, result.adev)
    assert np.all(np.abs(slopes[result.taus_s < 100] + 0.5) < 0.15)


def test_curve_is_read_only() -> None:
    result = curve("white")
    with pytest.raises(ValueError):
        result.adev[0] = 1.0


def test_adev_and_coefficients_of_a_full_paper_recording_take_seconds() -> None:
    """2 h at 200 Hz = 1.44 M samples; the budget is a few seconds (measured ~0.35 s)."""
    x = white(np.random.default_rng(1), 0.02, 200.0, 1_440_000) + rate_ramp(1e-4, 200.0, 1_440_000)
    start = time.perf_counter()
    result = allan_deviation(x, 200.0)
    coefficients = noise_coefficients(result)
    elapsed = time.perf_counter() - start
    assert elapsed < 10.0
    assert coefficients.n_mg_rt_s == pytest.approx(0.02, rel=0.05)
    assert coefficients.r_mg_per_s == pytest.approx(1e-4, rel=0.05)


# ---------------------------------------------------------------------------------------------
# noise coefficients
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["slopes", "model"])
@pytest.mark.parametrize("case", list(SINGLE_CASES))
def test_single_term_recovered_within_10_percent_and_only_it_is_observed(case: str, method: str) -> None:
    term, truth = SINGLE_CASES[case]
    coefficients = noise_coefficients(curve(case), method)
    assert getattr(coefficients, term) == pytest.approx(truth, rel=0.10)
    assert coefficients.fits[term].observed
    for other in TERMS:
        if other != term:
            assert not coefficients.fits[other].observed, other


def test_flicker_generator_is_flat_over_three_decades() -> None:
    result = curve("flicker")
    in_range = (result.taus_s >= 1.0) & (result.taus_s <= 1000.0)
    level = 0.02 * BIAS_INSTABILITY_FACTOR
    # Within the generator's ~4 % ripple plus 3 error bars of the estimate (~7 % at 1000 s).
    deviation = np.abs(result.adev - level)[in_range]
    assert np.all(deviation <= 0.04 * level + 3.0 * result.adev_err[in_range])
    assert np.all(deviation[result.taus_s[in_range] <= 100.0] <= 0.05 * level)
    fit = noise_coefficients(result).fits["b_mg"]
    assert fit.observed and fit.tau_range_s[0] <= 1.0
    assert math.log10(fit.tau_range_s[1] / fit.tau_range_s[0]) >= 2.5  # flat-slope run


def test_combination_each_term_read_in_its_own_region() -> None:
    coefficients = noise_coefficients(curve("combo"))
    assert coefficients.n_mg_rt_s == pytest.approx(COMBO_N, rel=0.15)
    assert coefficients.k_mg_per_rt_s == pytest.approx(COMBO_K, rel=0.15)
    assert coefficients.r_mg_per_s == pytest.approx(COMBO_R, rel=0.15)
    fits = coefficients.fits
    assert fits["n_mg_rt_s"].tau_range_s[1] < 3.0 < fits["k_mg_per_rt_s"].tau_range_s[0]
    assert fits["k_mg_per_rt_s"].tau_range_s[1] < 100.0 < fits["r_mg_per_s"].tau_range_s[0]
    assert all(fits[t].observed for t in ("n_mg_rt_s", "k_mg_per_rt_s", "r_mg_per_s"))
    assert not fits["q_mg"].observed and not fits["b_mg"].observed


def test_model_method_cross_checks_the_combination() -> None:
    coefficients = noise_coefficients(curve("combo"), method="model")
    assert coefficients.method == "model"
    assert coefficients.n_mg_rt_s == pytest.approx(COMBO_N, rel=0.10)
    assert coefficients.k_mg_per_rt_s == pytest.approx(COMBO_K, rel=0.15)
    assert coefficients.r_mg_per_s == pytest.approx(COMBO_R, rel=0.15)
    assert not coefficients.fits["q_mg"].observed and not coefficients.fits["b_mg"].observed


def test_white_plus_rrw_bowl_is_not_mistaken_for_a_bias_instability_floor() -> None:
    coefficients = noise_coefficients(curve("bowl"))
    assert coefficients.fits["n_mg_rt_s"].observed and coefficients.fits["k_mg_per_rt_s"].observed
    bias = coefficients.fits["b_mg"]
    assert not bias.observed
    # Still the catalogue's reading: the bowl's minimum over 0.664 (to within its error bar).
    result = curve("bowl")
    assert bias.value * BIAS_INSTABILITY_FACTOR == pytest.approx(result.adev.min(), rel=0.05)


def test_unobserved_terms_of_white_noise_are_the_largest_values_the_curve_allows() -> None:
    result = curve("white")
    upper = result.adev + result.adev_err
    coefficients = noise_coefficients(result)
    ramp = coefficients.fits["r_mg_per_s"]
    assert not ramp.observed and ramp.n_points == 1
    # The tightest bound: the r line (sigma = r tau / sqrt(2)) stays under the upper envelope
    # everywhere and touches it somewhere; the same for k (sigma = k sqrt(tau / 3)).
    ramp_ratio = ramp.value * result.taus_s / math.sqrt(2.0) / upper
    assert ramp_ratio.max() == pytest.approx(1.0, rel=1e-9)
    assert ramp.tau_range_s[0] > 0.5 * result.taus_s[-1]  # touches at the long-tau end
    rrw = coefficients.fits["k_mg_per_rt_s"]
    assert not rrw.observed
    assert (rrw.value * np.sqrt(result.taus_s / 3.0) / upper).max() == pytest.approx(1.0, rel=1e-9)
    # Bias instability: no floor, so the (upper) minimum of the whole curve, near its far end.
    bias = coefficients.fits["b_mg"]
    assert not bias.observed and bias.read_tau_s > 0.5 * result.taus_s[-1]
    assert bias.value == pytest.approx(upper.min() / BIAS_INSTABILITY_FACTOR)
    # MATLAB's literal rule reads the same terms off the point of closest local slope instead.
    literal = noise_coefficients(result, fallback="closest")
    slopes = local_slopes(result.taus_s, result.adev)
    i = int(np.argmin(np.abs(slopes - 1.0)))
    assert literal.r_mg_per_s == pytest.approx(result.adev[i] * math.sqrt(2.0) / result.taus_s[i])
    assert literal.b_mg == pytest.approx(result.adev.min() / BIAS_INSTABILITY_FACTOR)
    # ... which can never be a tighter bound than the curve's own envelope.
    assert literal.r_mg_per_s >= np.min(result.adev * math.sqrt(2.0) / result.taus_s) * (1 - 1e-12)


def test_constant_signal_gives_zero_unobserved_coefficients() -> None:
    for method in ("slopes", "model"):
        coefficients = noise_coefficients(allan_deviation(np.full(1000, 3.0), 1.0), method)
        assert all(coefficients.fits[t].value == 0.0 and not coefficients.fits[t].observed for t in TERMS)


def test_to_dict_is_plain() -> None:
    as_dict = noise_coefficients(curve("white")).to_dict()
    assert isinstance(as_dict["n_mg_rt_s"], float)
    assert isinstance(as_dict["fits"]["n_mg_rt_s"]["observed"], bool)  # type: ignore[index]


# ---------------------------------------------------------------------------------------------
# Table 1
# ---------------------------------------------------------------------------------------------


def _rounding_interval(value: float) -> tuple[float, float]:
    """Values that print as ``value`` with 3 significant digits."""
    half_unit = 0.005 * 10.0 ** math.floor(math.log10(value))
    return value - half_unit, value + half_unit


def test_improvement_formula_reproduces_the_papers_table_1() -> None:
    raw = {"b_mg": 5.43e-4, "k_mg_per_rt_s": 4.33e-5, "r_mg_per_s": 1.18e-6}
    paper = {  # method: (B, K, R) values, improvements, Aver as printed in Table 1
        "DLSTM": ((6.97e-5, 4.19e-6, 1.11e-7), (87.16, 90.33, 90.59), 89.36),
        "DLSTM + SSA": ((6.33e-5, 3.39e-6, 9.40e-8), (88.35, 92.16, 92.05), 90.85),
        "DLSTM + ISSA": ((2.77e-5, 1.14e-6, 2.63e-8), (94.89, 97.37, 97.77), 96.68),
        "PLA": ((5.25e-4, 3.45e-5, 8.24e-7), (3.29, 20.23, 30.31), 17.94),
    }
    for values, improvements, average in paper.values():
        for term, value, printed in zip(raw, values, improvements, strict=True):
            # The paper computed from unrounded coefficients: the printed improvement must lie
            # within what the 3-digit rounding of raw and compensated values allows.
            r_lo, r_hi = _rounding_interval(raw[term])
            c_lo, c_hi = _rounding_interval(value)
            lowest, highest = improvement_percent(r_lo, c_hi), improvement_percent(r_hi, c_lo)
            assert lowest - 0.005 <= printed <= highest + 0.005
            assert improvement_percent(raw[term], value) == pytest.approx(printed, abs=0.3)
        assert float(np.mean(improvements)) == pytest.approx(average, abs=0.006)
    assert math.isnan(improvement_percent(0.0, 1.0))


@cache
def table_signals() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    rng = np.random.default_rng(7)
    size, n, r = 200_000, 0.005, 1e-3
    noise = white(rng, n, FS, size)
    raw = noise + rate_ramp(r, FS, size)
    return raw, {"half ramp": noise + rate_ramp(r / 2, FS, size), "persistence": np.diff(raw, prepend=raw[0])}


def test_allan_table_arithmetic_matches_a_hand_computation() -> None:
    raw, compensated = table_signals()
    table = allan_table(raw, compensated, FS)
    assert list(table.compensated) == ["half ramp", "persistence"]
    assert list(table.curves) == ["Validation Data", "half ramp", "persistence"]
    raw_c = noise_coefficients(allan_deviation(raw, FS))
    for name, signal_ in compensated.items():
        comp_c = noise_coefficients(allan_deviation(signal_, FS))
        hand = {
            t: (getattr(raw_c, t) - getattr(comp_c, t)) / getattr(raw_c, t) * 100
            for t in ("b_mg", "k_mg_per_rt_s", "r_mg_per_s")
        }
        assert dict(table.improvement_pct[name]) == pytest.approx(hand, rel=1e-12)
        assert table.average_improvement_pct[name] == pytest.approx(sum(hand.values()) / 3, rel=1e-12)
    # Independent expectation: halving a deterministic ramp halves R.
    assert table.improvement_pct["half ramp"]["r_mg_per_s"] == pytest.approx(50.0, abs=3.0)
    # The caveat of docs/allan.md: any high-pass operation scores near 100 %.
    assert table.average_improvement_pct["persistence"] > 99.9


def test_renderers_use_the_papers_layout_and_are_deterministic() -> None:
    raw, compensated = table_signals()
    table = allan_table(raw, compensated, FS)
    markdown = table.to_markdown()
    lines = markdown.splitlines()
    assert lines[0] == "|  | Validation Data | half ramp | Improvement (%) | persistence | Improvement (%) |"
    assert [line.split(" | ")[0] for line in lines[2:6]] == [
        "| B (mg)",
        "| K (mg/s^1/2)",
        "| R (mg/s)",
        "| Aver (%)",
    ]
    r_row = lines[4].split(" | ")
    assert r_row[1].rstrip("†") == _sci_md(table.raw.r_mg_per_s)
    assert r_row[3] == f"{table.improvement_pct['half ramp']['r_mg_per_s']:.2f}"
    assert "†" in markdown  # white noise + ramp has no K region: flagged
    text = table.to_text()
    assert text.splitlines()[0].split() == ["Validation", "Data", "half", "ramp", "Improvement", "(%)",
                                            "persistence", "Improvement", "(%)"]  # fmt: skip
    assert f"{table.raw.r_mg_per_s:.2e}" in text
    assert "Aver (%)" in text and "K (mg/s^1/2)" in text
    again = allan_table(raw, compensated, FS)
    assert again.to_markdown() == markdown and again.to_text() == text


def _sci_md(value: float) -> str:
    mantissa, exponent = f"{value:.2e}".split("e")
    superscript = str(int(exponent)).translate(str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return f"{mantissa}×10{superscript}"


def test_allan_table_rejects_a_method_named_like_the_raw_column() -> None:
    raw, _ = table_signals()
    with pytest.raises(ValueError):
        allan_table(raw, {"Validation Data": raw}, FS)


# ---------------------------------------------------------------------------------------------
# Figure 13
# ---------------------------------------------------------------------------------------------


def test_plot_allan_writes_a_png(tmp_path) -> None:
    path = plot_allan({"white": curve("white"), "rrw": curve("rrw")}, tmp_path / "adev.png", title="t")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 10_000
    assert not list(tmp_path.glob("*.part*"))
    with pytest.raises(ValueError):
        plot_allan({}, tmp_path / "empty.png")
