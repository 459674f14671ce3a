"""PLA and cubic baselines recover known drift laws and behave as documented at the range edges."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from tests.testmodels import baseline_checkpoint, save_checkpoint
from trainer.baselines.pla import PiecewiseLinear
from trainer.baselines.poly3 import CubicPolynomial, bin_by_temperature
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import UserError, run_cli


def _ramp(n: int = 24_000, lo: float = -40.0, hi: float = 80.0) -> np.ndarray:
    return np.linspace(lo, hi, n)


def test_pla_recovers_known_lines_per_interval() -> None:
    temp = _ramp()
    edges = np.linspace(-40.0, 80.0, 11)
    rng = np.random.default_rng(3)
    true_k, true_b = rng.normal(0, 0.2, 10), rng.normal(0, 3.0, 10)
    index = np.clip(np.searchsorted(edges[1:-1], temp, side="right"), 0, 9)
    drift = true_k[index] * temp + true_b[index]
    model = PiecewiseLinear(10).fit_arrays(temp, drift)
    np.testing.assert_allclose(model.split_points_c, edges[1:-1], atol=1e-12)
    np.testing.assert_allclose(model.slopes_mg_per_c, true_k, atol=1e-9)
    np.testing.assert_allclose(model.intercepts_mg, true_b, atol=1e-7)
    np.testing.assert_allclose(model.drift_at(temp), drift, atol=1e-7)


def test_pla_least_squares_under_noise_matches_polyfit_per_interval() -> None:
    rng = np.random.default_rng(7)
    temp = np.sort(rng.uniform(-10, 50, 5_000))
    drift = 0.01 * temp**2 + rng.normal(0, 0.5, temp.size)
    model = PiecewiseLinear(4).fit_arrays(temp, drift)
    edges = np.linspace(temp.min(), temp.max(), 5)
    for k in range(4):
        upper_ok = temp < edges[k + 1] if k < 3 else np.ones_like(temp, dtype=bool)
        mask = (temp >= edges[k]) & upper_ok
        slope, intercept = np.polyfit(temp[mask], drift[mask], 1)
        assert model.slopes_mg_per_c[k] == pytest.approx(slope, rel=1e-9, abs=1e-12)
        assert model.intercepts_mg[k] == pytest.approx(intercept, rel=1e-9, abs=1e-9)


def test_pla_extrapolates_end_lines_outside_the_trained_range() -> None:
    temp = _ramp(2_000, 0.0, 50.0)
    drift = 0.3 * temp - 2.0 + 0.002 * temp**2
    model = PiecewiseLinear(10).fit_arrays(temp, drift)
    below, above = np.array([-20.0]), np.array([90.0])
    assert model.drift_at(below)[0] == pytest.approx(
        model.slopes_mg_per_c[0] * -20.0 + model.intercepts_mg[0]
    )
    assert model.drift_at(above)[0] == pytest.approx(
        model.slopes_mg_per_c[-1] * 90.0 + model.intercepts_mg[-1]
    )
    assert model.out_of_range(np.array([-0.1, 0.0, 50.0, 50.1])).tolist() == [True, False, False, True]


def test_pla_empty_interval_borrows_its_neighbours_line() -> None:
    temp = np.concatenate([np.linspace(0, 10, 500), np.linspace(90, 100, 500)])
    drift = 0.5 * temp
    model = PiecewiseLinear(10).fit_arrays(temp, drift)
    assert np.all(np.isfinite(model.slopes_mg_per_c))
    np.testing.assert_allclose(model.drift_at(temp), drift, atol=1e-9)


def test_pla_rejects_constant_temperature() -> None:
    with pytest.raises(UserError, match="does not vary"):
        PiecewiseLinear().fit_arrays(np.full(100, 25.0), np.zeros(100))


def test_poly3_recovers_a_known_cubic_about_the_mid_range_reference() -> None:
    temp = _ramp(100_000)
    coeffs = np.array([1.5, 0.08, -1.2e-3, 2.0e-5])  # about T_ref = 20 degC
    drift = np.polynomial.polynomial.polyval(temp - 20.0, coeffs)
    model = CubicPolynomial().fit_arrays(temp, drift)
    assert model.t_ref_c == pytest.approx(20.0)
    np.testing.assert_allclose(model.coefficients, coeffs, rtol=1e-4, atol=1e-6)


def test_poly3_clips_temperature_to_the_valid_range() -> None:
    temp = _ramp(10_000, -10.0, 60.0)
    drift = 0.01 * (temp - 25.0) ** 3 / 100
    model = CubicPolynomial().fit_arrays(temp, drift)
    edge_lo, edge_hi = model.drift_at(np.array([-10.0, 60.0]))
    np.testing.assert_allclose(model.drift_at(np.array([-40.0, 100.0])), [edge_lo, edge_hi])


def test_poly3_px4_mode_removes_the_median_offset() -> None:
    temp = _ramp(10_000)
    drift = 7.0 + 0.05 * (temp - 20.0)
    px4 = CubicPolynomial(remove_median=True).fit_arrays(temp, drift)
    full = CubicPolynomial().fit_arrays(temp, drift)
    assert full.coefficients[0] == pytest.approx(7.0, abs=1e-6)
    assert px4.coefficients[0] == pytest.approx(7.0 - np.median(drift), abs=1e-6)


def test_poly3_binning_equalises_uneven_heating() -> None:
    # Nine tenths of the samples sit in the first 10 degC: without bins they would dominate.
    rng = np.random.default_rng(11)
    temp = np.concatenate([rng.uniform(0, 10, 90_000), rng.uniform(10, 100, 10_000)])
    t_bins, v_bins = bin_by_temperature(temp, temp * 2.0, 100)
    assert t_bins.size == 100
    np.testing.assert_allclose(v_bins, 2.0 * t_bins)
    assert np.all(np.diff(t_bins) > 0)


def test_a_pla_whose_split_points_are_out_of_order_is_one_line_in_every_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The interval lookup (numpy's and the C's) needs sorted split points; a hand-edited model with
    two swapped is refused by evaluate, report and codegen alike, in the same line, nothing written
    (before, evaluate ran it and only codegen refused)."""
    temp = np.concatenate([np.linspace(40.0, -10.0, 300), np.linspace(-10.0, 40.0, 300)])
    columns = {"time_s": np.arange(temp.size, dtype=float), "temp_c": temp, "accel_mg": 0.01 * temp**2}
    rec = Recording(columns, {"sample_rate_hz": "1"}, "pla")
    recording = tmp_path / "rec.csv"
    write_recording(rec, recording)
    checkpoint = baseline_checkpoint("pla", rec)
    splits = checkpoint["payload"]["split_points_c"].clone()
    splits[[2, 3]] = splits[[3, 2]]
    checkpoint["payload"]["split_points_c"] = splits
    model = tmp_path / "edited.pt"
    save_checkpoint(checkpoint, model)
    lines = set()
    for main, argv in (
        (trainer_main, ["evaluate", str(model), str(recording), "--out-dir", str(tmp_path / "ev")]),
        (trainer_main, ["report", str(model), "--recording", str(recording), "-o", str(tmp_path / "rp")]),
        (codegen_main, ["export", str(model), "-o", str(tmp_path / "c")]),
    ):
        assert run_cli(main, argv) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "split_points_c must be in ascending order" in err and str(model) in err
        lines.add(err)
    assert len(lines) == 1
    assert not any((tmp_path / name).exists() for name in ("ev", "rp", "c"))
