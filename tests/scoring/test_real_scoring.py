"""Scoring real recordings (no ``true_*`` columns): drift left as the deviation from a constant,
per heating/cooling branch, the noise floor, ``--holdout``, ``--inject`` and the warning when the
validation data is the training data."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from trainer.cli import main
from trainer.data.holdout import Holdout, overlap_warning, parse_holdout, split
from trainer.data.recording import Recording, data_fingerprint
from trainer.data.recording_io import write_recording
from trainer.errors import UserError, run_cli
from trainer.fitting import fit_compensator, training_stats
from trainer.scoring.inject import injected_input, input_kept
from trainer.scoring.static import (
    COOLING,
    HEATING,
    NEITHER,
    noise_floor_mg,
    static_drift_left,
    thermal_branch,
)

RATE_HZ = 2.0
LOOP_MG = 3.0  # heating reads +3 mg, cooling -3 mg at the same temperature


def chamber_cycle(n: int = 3000, seed: int = 0) -> Recording:
    """A real-looking static run without ground truth: two cycles between -10 and 60 degC at 2 Hz
    (each half covers the whole range), gravity, a cubic drift, a heating/cooling loop, white noise."""
    k = np.arange(n)
    knots = np.array([0.0, 0.1, 0.35, 0.6, 0.85, 1.0]) * (n - 1)
    temp = np.interp(k, knots, [25.0, -10.0, 60.0, -10.0, 60.0, 25.0])
    rate = np.gradient(temp)
    loop = LOOP_MG * np.sign(rate)
    drift = 0.2 * (temp - 25) + 1e-4 * (temp - 25) ** 3 + loop
    accel = -975.0 + drift + np.random.default_rng(seed).normal(0.0, 0.3, n)
    columns = {"time_s": k / RATE_HZ, "temp_c": temp, "accel_mg": accel}
    return Recording(columns, {"sample_rate_hz": str(RATE_HZ)}, "chamber.csv")


def test_branches_follow_the_temperature_rate_with_a_dead_band() -> None:
    n = 1200
    temp = np.concatenate([np.linspace(0, 30, n), np.full(n, 30.0), np.linspace(30, 0, n)])
    branch = thermal_branch(temp, RATE_HZ)
    assert np.all(branch[100 : n - 100] == HEATING)  # 30 degC over 10 min = 3 degC/min
    assert np.all(branch[n + 100 : 2 * n - 100] == NEITHER)  # a dwell is neither
    assert np.all(branch[2 * n + 100 : 3 * n - 100] == COOLING)


def test_static_drift_left_is_the_deviation_from_one_constant() -> None:
    branch = np.array([HEATING] * 4 + [COOLING] * 4 + [NEITHER] * 2)
    x = np.array([1, 1, 1, 1, -1, -1, -1, -1, 0, 0], dtype=float) + 500.0
    left = static_drift_left(x, branch)
    assert left.rms_mg == pytest.approx(math.sqrt(0.8))
    assert left.max_abs_mg == pytest.approx(1.0)
    assert left.heating_rms_mg == pytest.approx(1.0) and left.cooling_rms_mg == pytest.approx(1.0)
    assert math.isnan(static_drift_left(x[:4], branch[:4]).cooling_rms_mg)


def test_noise_floor_of_white_noise_after_a_moving_average() -> None:
    x = np.random.default_rng(1).normal(0.0, 0.5, 200_000) + np.linspace(0, 20, 200_000)
    assert noise_floor_mg(x) == pytest.approx(0.5, rel=0.02)
    assert noise_floor_mg(x, 25) == pytest.approx(0.1, rel=0.02)


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("0.3", Holdout("last", fraction=0.3)),
        ("last:0.3", Holdout("last", fraction=0.3)),
        ("first:0.25", Holdout("first", fraction=0.25)),
        ("600:", Holdout("last", boundary_s=600.0)),
        (":600", Holdout("first", boundary_s=600.0)),
    ],
)
def test_holdout_grammar(spec: str, expected: Holdout) -> None:
    assert parse_holdout(spec) == expected


@pytest.mark.parametrize("spec", ["0", "1.5", "middle:0.2", "100:200", "first:x", "abc"])
def test_bad_holdout_is_a_one_line_error(spec: str) -> None:
    with pytest.raises(UserError, match="--holdout"):
        parse_holdout(spec)


def test_split_both_ways_round_and_by_time() -> None:
    rec = chamber_cycle(1000)
    train, valid = split(rec, parse_holdout("0.3"))
    assert (len(train), len(valid)) == (700, 300)
    assert valid.time_s[0] == rec.time_s[700] and train.time_s[-1] == rec.time_s[699]
    train, valid = split(rec, parse_holdout("first:0.3"))
    assert (len(train), len(valid)) == (700, 300) and train.time_s[0] == rec.time_s[300]
    train, valid = split(rec, parse_holdout(":100"))  # the first 100 s (200 rows) held out
    assert len(valid) == 200 and len(train) == 800
    with pytest.raises(UserError, match="each part"):
        split(rec, parse_holdout("0.001"))


def test_a_time_beyond_the_run_is_read_from_its_start() -> None:
    """A logger's Unix time as the boundary: the refusal says that T counts from the recording's
    start, and the run's duration."""
    rec = chamber_cycle(1000)
    logged = Recording({**rec.columns, "time_s": rec.time_s + 1.7e9}, dict(rec.meta), "logged.csv")
    duration_s = float(rec.time_s[-1] - rec.time_s[0])
    with pytest.raises(UserError, match=f"counts from the recording's start: 0 .. {duration_s:g} s"):
        split(logged, parse_holdout(f"{1.7e9 + 100:.0f}:"))
    _, valid = split(logged, parse_holdout("100:"))  # the same boundary from the start
    assert valid.time_s[0] - logged.time_s[0] == pytest.approx(100.0, abs=1.0)


def test_overlap_warning_only_when_validation_data_is_training_data() -> None:
    rec = chamber_cycle(1000)
    assert "is the training data" in str(overlap_warning(training_stats(rec), rec, data_fingerprint(rec)))
    train, valid = split(rec, parse_holdout("0.5"))
    assert overlap_warning(training_stats(train), valid, data_fingerprint(valid)) is None
    warning = overlap_warning(training_stats(train), rec, data_fingerprint(rec))
    assert warning is not None and "50.0 % of the validation rows" in warning


def test_injected_steps_survive_temperature_methods_not_recursive_ones() -> None:
    rec = chamber_cycle()
    train, valid = split(rec, parse_holdout("0.5"))
    steps = injected_input(valid, "steps")
    assert set(np.unique(steps)) == {0.0, 20.0, -20.0, 50.0, -50.0, 10.0}
    for method in ("pla", "poly3"):
        kept = input_kept(fit_compensator(method, train), valid, steps)
        assert kept.gain == pytest.approx(1.0, abs=1e-9) and kept.error_rms_mg < 1e-9
    kept = input_kept(fit_compensator("persistence", train), valid, steps)
    assert kept.gain < 0.05  # it follows the output: a 50 mg tilt is gone within a second


@pytest.fixture(scope="module")
def chamber_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("real") / "chamber.csv"
    write_recording(chamber_cycle(), path)
    return path


def _table_rows(printed: str) -> dict[str, list[str]]:
    rows = {}
    for line in printed.splitlines():
        if line.startswith("| ") and "---" not in line:
            cells = [c.strip() for c in line.strip("|").split("|")]
            rows[cells[0]] = cells[1:]
    return rows


@pytest.mark.parametrize("side", ["last:0.5", "first:0.5"])
def test_compare_scores_a_real_recording_held_out_both_ways(
    chamber_csv: Path, tmp_path: Path, side: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cmp"
    argv = ["compare", str(chamber_csv), "--holdout", side, "--inject", "steps", "--out-dir", str(out)]
    argv += ["--methods", "pla,poly3,persistence", "--quiet"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "warning" not in captured.err
    rows = _table_rows(captured.out)
    kept_column = next(i for i, c in enumerate(rows["method"]) if c.startswith("input kept"))
    for name in ("uncompensated", "pla", "poly3", "persistence"):
        drift_left = rows[name][:4]  # RMS, max, heating RMS, cooling RMS
        assert all(cell not in ("n/a", "") for cell in drift_left), (name, drift_left)
    assert float(rows["poly3"][0]) < float(rows["uncompensated"][0])
    # the loop is left (+-3 mg about one constant): no temperature function removes it
    assert float(rows["poly3"][2]) > 0.5 * LOOP_MG and float(rows["poly3"][3]) > 0.5 * LOOP_MG
    assert float(rows["poly3"][kept_column]) == pytest.approx(100.0, abs=0.1)  # injected steps kept
    assert float(rows["persistence"][kept_column]) < 5.0
    if "in training range RMS (mg)" in rows["method"]:  # part of the held-out half is outside the range
        inside = rows["method"].index("in training range RMS (mg)")
        assert float(rows["poly3"][inside]) > 0.0 and rows["noise floor (white noise)"][inside] == ""
    assert float(rows["noise floor (white noise)"][0]) == pytest.approx(0.3, rel=0.1)
    report = (out / "report.md").read_text()
    assert "deviation of the compensated output" in report and "held out" in report


def test_compare_warns_when_validation_is_the_training_data(
    chamber_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cmp"
    argv = ["compare", str(chamber_csv), str(chamber_csv), "--methods", "poly3", "--out-dir", str(out)]
    assert main([*argv, "--quiet"]) == 0
    assert "the validation data is the training data" in capsys.readouterr().err
    assert "the validation data is the training data" in (out / "report.md").read_text()


def test_compare_takes_at_most_one_of_valid_and_holdout(
    chamber_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Neither one cross-validates (tests/scoring/test_crossval.py); both at once is one line, nothing written."""
    out_dir = tmp_path / "cmp"
    argv = ["compare", str(chamber_csv), str(chamber_csv), "--holdout", "0.5", "--methods", "pla"]
    assert run_cli(main, [*argv, "--out-dir", str(out_dir)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "--holdout" in lines[0]
    assert not out_dir.exists()


def test_evaluate_scores_the_held_out_part_with_an_injection(
    chamber_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = chamber_cycle()
    train, _ = split(rec, parse_holdout("0.5"))
    train_csv = tmp_path / "train.csv"
    write_recording(train, train_csv)
    model = tmp_path / "m.pt"
    assert main(["fit", "--method", "poly3", str(train_csv), "-o", str(model)]) == 0
    capsys.readouterr()
    argv = ["evaluate", str(model), str(chamber_csv), "--holdout", "0.5", "--inject", "steps"]
    assert main([*argv, "--out-dir", str(tmp_path / "e")]) == 0
    printed = capsys.readouterr().out
    assert "drift left, deviation from a constant [poly3]" in printed and "noise floor" in printed
    assert "input kept [poly3]: 100.0 %" in printed
    assert "warning: the validation data" not in printed
    # the whole recording contains the training rows (written to another file: same data, new name)
    assert main(["evaluate", str(model), str(train_csv), "--out-dir", str(tmp_path / "e2")]) == 0
    assert "the validation data is the training data" in capsys.readouterr().out


def test_a_held_out_end_part_is_scored_after_the_training_part() -> None:
    """A stateful method's output on a held-out end part continues from the training part (firmware
    that has run since power-on); cold, it would start with an empty history."""
    from trainer.scoring.compare import compensate_after

    rec = chamber_cycle()
    train, valid = split(rec, parse_holdout("last:0.5"))
    model = fit_compensator("persistence", train)
    warm = compensate_after(model, valid, train)
    cold = model.compensate(valid)
    whole = model.compensate(rec)
    np.testing.assert_array_equal(warm, whole[len(train) :])
    # persistence subtracts the previous smoothed output: only the first window differs
    assert not np.array_equal(warm[:10], cold[:10])
    np.testing.assert_allclose(warm[200:], cold[200:], atol=1e-9)


def test_no_in_range_figure_from_fewer_samples_than_a_smoothing_window() -> None:
    """A held-out part that touches the training range at a few samples: their deviation from their
    own mean read 0, printed as the in-range figure. Fewer in-range samples than one smoothing window
    (at least 2) give no figure; a part with enough of them gives one."""
    from trainer.scoring.evaluate import evaluate

    rec = chamber_cycle(4000)
    rng = np.random.default_rng(5)
    output = rec.accel_mg + rng.normal(0.0, 1.0, len(rec))
    smoothing_s = 1.0
    window = max(2, round(smoothing_s * rec.sample_rate_hz))
    for inside, expected in ((window - 1, False), (20 * window, True)):
        outside = np.ones(len(rec), dtype=bool)
        outside[:inside] = False
        scored = evaluate(rec, {"m": output}, out_of_range={"m": outside}, smoothing_s=smoothing_s)
        assert ("m" in scored.static_in_range) is expected
        if expected:
            assert scored.static_in_range["m"].rms_mg > 0.0
