"""Blocked cross-validation over thermal segments, ``--method auto`` and its identity export."""

from __future__ import annotations

import itertools
import json
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from trainer import methods
from trainer.baselines.poly3 import CubicPolynomial
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import UserError, run_cli
from trainer.fitting import fit_compensator
from trainer.scoring.crossval import (
    UNCOMPENSATED,
    cross_validate,
    folds_of,
    impute_held_out,
    thermal_segments,
    training_rows,
)
from trainer.selection import NONE, choose, select

RATE_HZ = 2.0
# (temperature at the end of the leg, minutes): cooling, a 1-minute turn, heating, cooling
PROFILE = ((50.0, 0.0), (-15.0, 22.0), (-15.0, 1.0), (70.0, 28.0), (35.0, 14.0))


def profile_temperature() -> np.ndarray:
    temps = [np.array([PROFILE[0][0]])]
    for (start, _), (end, minutes) in itertools.pairwise(PROFILE):
        n = round(minutes * 60 * RATE_HZ)
        temps.append(np.linspace(start, end, n + 1)[1:])
    return np.concatenate(temps)


def chamber_run(drift_mg: np.ndarray | None = None, noise_mg: float = 0.05, seed: int = 0) -> Recording:
    """A cooling / heating / cooling run at 2 Hz with ``drift_mg`` (default: a cubic) plus white noise."""
    temp = profile_temperature()
    rng = np.random.default_rng(seed)
    if drift_mg is None:
        d = temp - 25.0
        drift_mg = 0.05 * d + 2e-3 * d**2 - 3e-5 * d**3
    accel = 1000.0 + drift_mg + rng.normal(0.0, noise_mg, temp.size)
    columns = {"time_s": np.arange(temp.size) / RATE_HZ, "temp_c": temp, "accel_mg": accel}
    return Recording(columns, {"sample_rate_hz": repr(RATE_HZ)}, "<chamber>")


def rms_about_mean(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean((x - x.mean()) ** 2)))


def test_segments_follow_the_profile_and_join_short_turns() -> None:
    rec = chamber_run()
    segments = thermal_segments(rec)
    assert [s.label for s in segments] == ["cooling", "heating", "cooling"]
    assert segments[0].start == 0 and segments[-1].stop == len(rec)
    assert all(a.stop == b.start for a, b in itertools.pairwise(segments))
    # the boundaries sit at the turning points of the set profile (within the rate window)
    turn_heating = round(23 * 60 * RATE_HZ)
    assert (
        abs(segments[1].start - round(22 * 60 * RATE_HZ)) < 90 or abs(segments[1].start - turn_heating) < 90
    )


def test_uncompensated_and_cubic_scores_match_an_independent_computation() -> None:
    rec = chamber_run()
    segments = thermal_segments(rec)

    def fit_cubic(train: Recording) -> CubicPolynomial:
        return CubicPolynomial(median_kernel=1, n_bins=0).fit(train)

    cv = cross_validate(rec, {"poly3": fit_cubic}, stateful=set(), smoothing_s=0.0)
    raw = cv.results[UNCOMPENSATED]
    for seg, fold in zip(segments, raw.folds, strict=True):
        assert fold.warm_rms == pytest.approx(rms_about_mean(rec.accel_mg[seg.start : seg.stop]))
    for seg, fold in zip(segments, cv.results["poly3"].folds, strict=True):
        keep = training_rows(len(rec), seg)
        d = rec.temp_c[keep] - rec.temp_c[keep].mean()
        coef = np.polyfit(d, rec.accel_mg[keep], 3)
        held = rec.accel_mg[seg.start : seg.stop] - np.polyval(
            coef,
            np.clip(rec.temp_c[seg.start : seg.stop], rec.temp_c[keep].min(), rec.temp_c[keep].max())
            - rec.temp_c[keep].mean(),
        )
        assert fold.warm_rms == pytest.approx(rms_about_mean(held), rel=1e-6)
        assert fold.warm_rms < 0.06  # the cubic drift is removed down to the 0.05 mg noise
    assert cv.results["poly3"].cv_rms < 0.1 * raw.cv_rms


def test_training_never_sees_the_held_out_output() -> None:
    rec = chamber_run()
    seen: list[tuple[str, Recording]] = []

    class Spy:
        def predict_drift(self, r: Recording) -> np.ndarray:
            return np.zeros(len(r))

    def spy(kind: str):  # type: ignore[no-untyped-def]
        def fit(train: Recording) -> Spy:
            seen.append((kind, train))
            return Spy()

        return fit

    cross_validate(rec, {"rows": spy("rows"), "state": spy("state")}, stateful={"state"}, smoothing_s=0.0)
    segments = thermal_segments(rec)
    rows_seen = [r for kind, r in seen if kind == "rows"]
    state_seen = [r for kind, r in seen if kind == "state"]
    for seg, train in zip(segments, rows_seen, strict=True):
        held_times = rec.time_s[seg.start : seg.stop]
        assert not np.isin(train.time_s, held_times).any()
        assert len(train) == len(rec) - (seg.stop - seg.start)
    for seg, train in zip(segments, state_seen, strict=True):
        # the whole temperature history, the held-out output replaced by the training rows' cubic
        assert np.array_equal(train.temp_c, rec.temp_c)
        expected = impute_held_out(rec, training_rows(len(rec), seg)).accel_mg
        assert np.array_equal(train.accel_mg, expected)
        assert not np.allclose(train.accel_mg[seg.start : seg.stop], rec.accel_mg[seg.start : seg.stop])


def _ramp(rows: int) -> Recording:
    temp = np.linspace(-20, 60, rows)
    drift = 0.01 * (temp + 30.0) ** 2  # a curve a straight line leaves, a quadratic removes
    return Recording(
        {"time_s": np.arange(temp.size) / RATE_HZ, "temp_c": temp, "accel_mg": drift},
        {"sample_rate_hz": "2.0"},
        "ramp.csv",
    )


def test_a_monotone_ramp_is_cross_validated_in_thirds() -> None:
    rec = _ramp(4000)
    (segment,) = thermal_segments(rec)
    cv = cross_validate(rec, {}, stateful=set(), smoothing_s=0.0)
    # thirds of the temperature span: each part starts at the first sample at or above its level
    first, second = (int(np.argmax(rec.temp_c >= -20.0 + 80.0 * k / 3)) for k in (1, 2))
    assert [(s.start, s.stop) for s in cv.segments] == [(0, first), (first, second), (second, 4000)]
    assert abs(first - 4000 / 3) <= 1 and abs(second - 8000 / 3) <= 1  # on a linear ramp, thirds in time
    assert all(s.label.startswith(segment.label) for s in cv.segments)

    def polynomial(degree: int) -> Callable[[Recording], object]:
        return lambda train: fit_compensator(methods.CUBIC, train, {"degree": degree})

    fitters = {f"poly{k}": polynomial(k) for k in (1, 2)}
    results = cross_validate(rec, fitters, stateful=set(), smoothing_s=0.0).results
    middle = {name: r.folds[1].warm_rms for name, r in results.items()}
    assert middle["poly2"] < 1e-3 * middle["poly1"] < middle[UNCOMPENSATED]  # the exact shape wins inside
    # the outer thirds lie outside the training range, where every model holds its edge value
    assert results["poly2"].folds[0].warm_rms == pytest.approx(results[UNCOMPENSATED].folds[0].warm_rms)
    with pytest.raises(
        UserError, match=r"ramp\.csv: cross-validation needs a run that heats and cools, or 48 rows"
    ):
        cross_validate(_ramp(40), {}, stateful=set(), smoothing_s=0.0)


def test_a_warm_up_is_cross_validated_in_thirds_of_its_temperature_span() -> None:
    """A fridge-to-room run (exponential approach, its slow end a dwell): the parts cover equal
    temperature spans, so the middle one interpolates over a third of the range and the cubic beats
    no compensation there (held out as its two thermal segments, each lay outside the other's range
    and the cubic left exactly what no compensation leaves)."""
    t = np.arange(0.0, 4 * 3600.0, 1.0)
    temp = 24.0 - 20.0 * np.exp(-t / 2400.0)
    rec = Recording(
        {"time_s": t, "temp_c": temp, "accel_mg": 0.01 * (temp + 30.0) ** 2},
        {"sample_rate_hz": "1.0"},
        "fridge.csv",
    )
    assert {s.label for s in thermal_segments(rec)} == {"heating", "dwell"}
    folds = folds_of(rec)
    assert [s.label for s in folds] == ["heating 1/3", "heating 2/3", "heating 3/3"]
    spans = [s.temp_to_c - s.temp_from_c for s in folds]
    assert spans == pytest.approx([20.0 / 3] * 3, abs=0.05)
    cubic = {"poly3": lambda train: fit_compensator(methods.CUBIC, train, {"degree": 3})}
    results = cross_validate(rec, cubic, stateful=set(), smoothing_s=0.0).results
    assert results["poly3"].folds[1].warm_rms < 0.01 * results[UNCOMPENSATED].folds[1].warm_rms


def test_auto_chooses_none_where_nothing_helps_and_a_polynomial_where_one_does() -> None:
    flat = chamber_run(drift_mg=np.zeros(profile_temperature().size))
    choice = select(flat, labels=("none", "poly1", "poly3"))
    assert choice.chosen == NONE  # every fit adds its own noise: none is never beaten on pure noise
    assert "no compensation" in choice.reason
    drifting = select(chamber_run(), labels=("none", "poly1", "poly2", "poly3"))
    assert drifting.chosen in ("poly2", "poly3")
    chosen_cv = drifting.cv.results[drifting.chosen].cv_rms
    assert chosen_cv < drifting.cv.results[UNCOMPENSATED].cv_rms
    assert all(chosen_cv <= 1.02 * drifting.cv.results[c].cv_rms for c in ("poly1", "poly2", "poly3"))


def test_the_rule_prefers_the_simpler_of_two_equal_candidates() -> None:
    cv = select(chamber_run(), labels=("none", "poly2", "poly3")).cv
    cv.results["poly2"].folds = list(cv.results["poly3"].folds)  # identical figures
    assert choose(cv)[0] == "poly2"


class Run(NamedTuple):
    """What a command left: its exit code and its captured output."""

    returncode: int
    stdout: str
    stderr: str


def _run(main: Callable[[list[str] | None], int], *args: str, capsys: pytest.CaptureFixture[str]) -> Run:
    """One command in-process through its entry point's ``run_cli`` (exit code, stdout, stderr)."""
    capsys.readouterr()
    code = run_cli(main, list(args))
    out, err = capsys.readouterr()
    return Run(code, out, err)


def test_fit_auto_and_export_of_an_uncompensated_channel(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    temp = profile_temperature()
    rng = np.random.default_rng(3)
    d = temp - 25.0
    columns = {
        "time_s": np.arange(temp.size) / RATE_HZ,
        "temp_c": temp,
        "accel0_z_mg": -1000.0 + 0.1 * d + 3e-3 * d**2 + rng.normal(0, 0.05, temp.size),
        "gyro0_x_dps": rng.normal(0.0, 0.01, temp.size),  # no drift: nothing can help it
    }
    columns["accel_mg"] = columns["accel0_z_mg"]
    write_recording(Recording(columns, {"sample_rate_hz": "2.0"}, "imu"), tmp_path / "imu.csv")
    fit = _run(
        trainer_main,
        "fit",
        "--method",
        "auto",
        "--candidates",
        "none,poly1,poly3",
        "imu.csv",
        "--channels",
        "all",
        "-o",
        "m",
        capsys=capsys,
    )
    assert fit.returncode == 0, fit.stderr
    assert "auto: chose none" in fit.stdout and "deg/s" in fit.stdout
    # progress says which channel of how many, and which fit of the channel's cross-validation
    progress = [line for line in fit.stderr.splitlines() if "cross-validation:" in line]
    folds = len(folds_of(Recording(columns, {"sample_rate_hz": "2.0"}, "imu")))
    fits = 2 * folds  # poly1 and poly3 (none is the uncompensated row, not fitted)
    assert len(progress) == 2 * fits
    assert (
        progress[0].startswith("[accel0_z, channel 1 of 2] ") and f"(fit 1 of {fits} done in " in progress[0]
    )
    assert (
        progress[-1].startswith("[gyro0_x, channel 2 of 2] ")
        and f"(fit {fits} of {fits} done in " in progress[-1]
    )
    index = json.loads((tmp_path / "m" / "channels.json").read_text())
    chosen = {c["channel"]: c["auto_chose"] for c in index["channels"]}
    assert chosen["gyro0_x"] == NONE and chosen["accel0_z"] != NONE
    # each line names what was chosen, not the class that loads it (a degree-0 poly3 is "none")
    assert f"{NONE} gyro0_x: fitted on" in fit.stdout and "poly3 gyro0_x" not in fit.stdout
    assert f"{chosen['accel0_z']} accel0_z: fitted on" in fit.stdout
    out = _run(
        codegen_main,
        "export",
        "m",
        "--channels",
        "all",
        "--format",
        "px4-params",
        "--device-id",
        "accel0=1,gyro0=2",
        "-o",
        "params",
        capsys=capsys,
    )
    assert out.returncode == 0, out.stderr
    assert "gyro0_x is exported as the identity" in out.stdout
    # PX4's republish lag bound is said of a compensated channel only (not "up to 0 deg/s" of the identity)
    assert "gyro0_x: PX4 updates the applied offset" not in out.stdout
    assert "accel0_z: PX4 updates the applied offset" in out.stdout
    assert "the model has no drift: the channel's level stays in the output" in fit.stdout  # not "the 0 mg"
    params = (tmp_path / "params" / "px4_thermal.params").read_text()
    # PX4's TC_G_ENABLE switches every gyro instance: an identity set leaves it alone (zero coefficients)
    values = {
        row.split("\t")[2]: row.split("\t")[3] for row in params.splitlines() if not row.startswith("#")
    }
    assert "TC_G_ENABLE" not in values and values["TC_A_ENABLE"] == "1" and values["TC_G0_X1_0"] == "0"
    assert "TC_G_ENABLE, which switches every gyro instance, is left as the vehicle has it" in params
    assert "# gyro0_x: model sha256 " in params and "(the identity: no compensation left less drift" in params
    # the C headers name what auto chose (the identity is "none"), not the class that loads it (poly3)
    assert (
        _run(codegen_main, "export", "m/gyro0_x.pt", "-o", "one", "--name", "gx", capsys=capsys).returncode
        == 0
    )
    assert 'method "none"' in (tmp_path / "one" / "gx.h").read_text()
    assert (
        _run(
            codegen_main, "export", "m", "--channels", "all", "-o", "imu", "--name", "imu", capsys=capsys
        ).returncode
        == 0
    )
    assert "1: gyro0_x [deg/s], none," in (tmp_path / "imu" / "imu.h").read_text()
    signoff = _run(
        trainer_main,
        "report",
        "m/accel0_z.pt",
        "m/gyro0_x.pt",
        "--recording",
        "imu.csv",
        "-o",
        "so",
        capsys=capsys,
    )
    assert signoff.returncode in (0, 1), signoff.stderr
    text = (tmp_path / "so" / "report.md").read_text()
    assert text.count("### Cross-validation") == 2 and "cross-validated over 3 thermal segments" in text
    assert "worse than uncompensated" not in text  # auto never ships a channel CV says is made worse
    assert f"gyro0_x / {NONE}" in text and "method `none`" in text
    bad = _run(
        trainer_main,
        "fit",
        "--method",
        "poly3",
        "--candidates",
        "none",
        "imu.csv",
        "-o",
        "x.pt",
        capsys=capsys,
    )
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "--candidates applies" in bad.stderr


def test_compare_without_validation_cross_validates(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    write_recording(chamber_run(), tmp_path / "run.csv")
    out = _run(
        trainer_main,
        "compare",
        "run.csv",
        "--methods",
        "poly3,pla,dlstm",
        "--out-dir",
        "cv",
        "--quiet",
        capsys=capsys,
    )
    assert out.returncode == 0, out.stderr
    data = json.loads((tmp_path / "cv" / "crossval.json").read_text())
    assert set(data["methods"]) == {UNCOMPENSATED, "poly3", "pla"} and "dlstm" in data["skipped"]
    assert len(data["segments"]) == 3
    report = (tmp_path / "cv" / "report.md").read_text()
    assert "| uncompensated |" in report and "not cross-validated" in report
    refused = _run(trainer_main, "compare", "run.csv", "--inject", "steps", "--out-dir", "x", capsys=capsys)
    assert refused.returncode == 2 and "Traceback" not in refused.stderr and not (tmp_path / "x").exists()


def test_explicit_folds_replace_the_thermal_segments() -> None:
    rec = chamber_run()
    (first, *_) = thermal_segments(rec)
    half = (first.start + first.stop) // 2
    folds = [replace(first, stop=half), replace(first, start=half)]
    seen: list[int] = []

    def fit_cubic(train: Recording) -> CubicPolynomial:
        seen.append(len(train))
        return CubicPolynomial(median_kernel=1, n_bins=0).fit(train)

    cv = cross_validate(rec, {"poly3": fit_cubic}, stateful=set(), smoothing_s=0.0, fold_segments=folds)
    assert cv.segments == folds
    assert seen == [len(rec) - (half - first.start), len(rec) - (first.stop - half)]  # trained on the rest
    assert len(cv.results["poly3"].folds) == len(cv.results[UNCOMPENSATED].folds) == 2


def test_a_physics_fold_clamps_to_the_temperatures_it_trains_on() -> None:
    """A fold trained on the first cooling only (50 to -15 degC) sees the whole run's temperature
    (up to 70 degC) with the rest imputed. Its physics model holds its edge value above 50 degC as
    the same model trained with ``--holdout`` on those rows does: on a held-out part outside the
    rows it learned from it leaves what the cubic leaves, not an extrapolation of its backbone."""
    rec = chamber_run()
    first_cooling = thermal_segments(rec)[0]
    train = ~training_rows(len(rec), first_cooling)
    model = fit_compensator(methods.PHYSICS, impute_held_out(rec, train), {"effects": "thermal_lag"}, None)
    rows = rec.temp_c[train]
    assert model.temp_range_c == (float(rows.min()), float(rows.max()))  # type: ignore[attr-defined]
    assert float(rows.max()) < float(rec.temp_c.max())  # the premise: the imputed rows reach further


def test_a_thermometer_read_to_one_degree_cuts_the_same_segments() -> None:
    """A cycle at 1.1 degC/min read to 1 degC holds each reading for about a minute: over the 60 s
    rate window the samples alternated between ramp and dwell, and the whole cycle came out as one
    cooling segment (``auto`` then judged a run that does not reverse). Rounded, it cuts the same
    segments as the exact temperature, within two minutes of its turns."""
    minutes = np.r_[0.0, 40.0, 120.0, 160.0]
    t_s = np.arange(0.0, minutes[-1] * 60.0, 1.0 / RATE_HZ)
    exact = np.interp(t_s, minutes * 60.0, [25.0, -20.0, 60.0, 25.0])
    noise = np.random.default_rng(3).normal(0.0, 0.05, t_s.size)

    def run(temp: np.ndarray) -> Recording:
        columns = {"time_s": t_s, "temp_c": temp, "accel_mg": 1000.0 + noise}
        return Recording(columns, {"sample_rate_hz": repr(RATE_HZ)}, "<slow cycle>")

    reference = thermal_segments(run(exact))
    rounded = thermal_segments(run(np.round(exact)))
    assert [s.label for s in reference] == ["cooling", "heating", "cooling"]
    assert [s.label for s in rounded] == [s.label for s in reference]
    for a, b in zip(rounded[1:], reference[1:], strict=True):
        assert abs(a.t0_s - b.t0_s) <= 120.0


def test_a_part_s_segments_are_named_on_the_run_s_clock() -> None:
    """A part cut by --holdout names its segments in the times --holdout counts in (from the run's
    start), not from the part's own first sample: the user reads them against the recording."""
    from trainer.data.holdout import parse_holdout, split

    rec = chamber_run()
    t = rec.time_s - rec.time_s[0]
    train, _ = split(rec, parse_holdout("first:0.3"))
    start_s = float(train.time_s[0] - rec.time_s[0])
    assert start_s > 0.0
    segments = folds_of(train)
    for segment in segments:
        assert segment.t0_s == pytest.approx(float(t[len(rec) - len(train) + segment.start]))
        assert f"{segment.t0_s:.0f}-" in segment.name
    assert segments[0].t0_s == pytest.approx(start_s)
