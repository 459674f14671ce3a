"""Offset and gravity safety (trainer/reference.py): temperature-driven methods model the drift
relative to T_ref by default, an absolute constant above 100 mg is refused, ``fit`` and ``codegen
export`` say what they remove, and recursive methods say that they remove sustained inputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from codegen.cli import main as codegen_main
from trainer.checkpoint import load_checkpoint, load_model, save_model
from trainer.cli import main
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording
from trainer.dlstm.fusion import FusionSettings
from trainer.errors import UserError, run_cli
from trainer.fitting import fit_compensator
from trainer.reference import (
    OFFSET_LIMIT_MG,
    OffsetPolicy,
    OffsetRecord,
    reference_temperature,
    value_at_temperature,
)
from trainer.scoring.evaluate import drift_score
from trainer.train_stats import TrainStats

GRAVITY_MG = -981.0
RATE_HZ = 2.0


def cubic_drift(temp_c: np.ndarray) -> np.ndarray:
    """The sensor's thermal drift (mg): not zero anywhere near the range mid-point."""
    return 4.0 + 0.3 * (temp_c - 20.0) - 2e-3 * (temp_c - 20.0) ** 2 + 4e-5 * (temp_c - 20.0) ** 3


def static_run(offset_mg: float, n: int = 2400, seed: int = 0) -> Recording:
    """A static chamber run at 2 Hz: -10 -> 50 -> 0 degC, ``offset_mg`` + drift + white noise."""
    t = np.arange(n) / RATE_HZ
    temp = np.interp(np.arange(n), [0, n // 2, n - 1], [-10.0, 50.0, 0.0])
    rng = np.random.default_rng(seed)
    accel = offset_mg + cubic_drift(temp) + rng.normal(0.0, 0.2, n)
    columns = {"time_s": t, "temp_c": temp, "accel_mg": accel, "true_drift_mg": cubic_drift(temp)}
    return Recording(columns, {"sample_rate_hz": str(RATE_HZ)}, "static.csv")


def test_reference_temperature_is_the_mid_point_or_the_users_value() -> None:
    temp = np.array([-10.0, 5.0, 50.0])
    assert reference_temperature(temp) == pytest.approx(20.0)
    assert reference_temperature(temp, 0.0) == 0.0
    with pytest.raises(UserError, match="--tref"):
        reference_temperature(temp, 60.0)


def test_value_at_temperature_of_a_line_and_of_a_loop() -> None:
    temp = np.linspace(0.0, 40.0, 401)
    assert value_at_temperature(temp, 3.0 * temp - 2.0, 17.3) == pytest.approx(3.0 * 17.3 - 2.0)
    # a loop: heating reads +1 mg, cooling -1 mg at the same temperature; the middle is 0
    both = np.concatenate([temp, temp[::-1]])
    values = np.concatenate([np.full(401, 1.0), np.full(401, -1.0)])
    assert value_at_temperature(both, values, 20.0) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("method", ["pla", "poly3"])
def test_relative_fit_removes_only_the_temperature_dependent_part(method: str) -> None:
    rec = static_run(GRAVITY_MG)
    model = fit_compensator(method, rec)
    assert model.offset is not None and model.offset.mode == "relative"
    t_ref = 20.0  # (-10 + 50) / 2
    assert model.offset.t_ref_c == pytest.approx(t_ref)
    assert model.offset.drift_at_t_ref_mg == pytest.approx(GRAVITY_MG + cubic_drift(np.array(t_ref)), abs=0.3)
    assert model.offset.removed_mg == 0.0
    temp = np.linspace(-5.0, 45.0, 11)
    estimate = model.drift_at(temp)  # type: ignore[attr-defined]
    expected = cubic_drift(temp) - cubic_drift(np.array(t_ref))
    np.testing.assert_allclose(estimate, expected, atol=0.4)
    # the compensated output keeps gravity (the accelerometer calibration's job)
    assert np.mean(model.compensate(rec.without_truth())) == pytest.approx(
        GRAVITY_MG + cubic_drift(np.array(t_ref)), abs=0.5
    )


def test_absolute_fit_removes_the_constant_and_refuses_gravity() -> None:
    small = fit_compensator("poly3", static_run(0.0), policy=OffsetPolicy("absolute"))
    assert small.offset is not None
    assert small.offset.removed_mg == pytest.approx(cubic_drift(np.array(20.0)), abs=0.3)
    np.testing.assert_allclose(
        small.drift_at(np.array([0.0, 40.0])),  # type: ignore[attr-defined]
        cubic_drift(np.array([0.0, 40.0])),
        atol=0.4,
    )
    with pytest.raises(UserError, match="--offset") as info:
        fit_compensator("poly3", static_run(GRAVITY_MG), policy=OffsetPolicy("absolute"))
    assert f"above {OFFSET_LIMIT_MG:g} mg" in str(info.value)
    forced = fit_compensator("pla", static_run(GRAVITY_MG), policy=OffsetPolicy("absolute-unbounded"))
    assert forced.offset is not None and forced.offset.removed_mg == pytest.approx(GRAVITY_MG + 4.0, abs=0.5)


def test_a_user_reference_temperature_moves_the_zero() -> None:
    model = fit_compensator("poly3", static_run(GRAVITY_MG), policy=OffsetPolicy("relative", 0.0))
    assert model.drift_at(np.array([0.0]))[0] == pytest.approx(0.0, abs=1e-9)  # type: ignore[attr-defined]
    assert model.drift_at(np.array([40.0]))[0] == pytest.approx(  # type: ignore[attr-defined]
        cubic_drift(np.array(40.0)) - cubic_drift(np.array(0.0)), abs=0.4
    )


def test_temperature_dlstm_shift_moves_every_estimate_by_the_constant() -> None:
    torch.manual_seed(0)
    rec = static_run(GRAVITY_MG, n=600).without_truth()
    settings = FusionSettings(population=1, iterations=3, cycles=0)
    model = fit_compensator("dlstm-temp", rec, {"settings": settings, "progress": False})
    assert model.offset is not None
    # after the relative shift its estimate at T_ref on the training run is zero ...
    assert model.drift_at_reference(model.offset.t_ref_c, RATE_HZ, rec) == pytest.approx(0.0, abs=1e-6)
    # ... and a shift moves every estimate by exactly the shift
    before = model.predict_drift(rec)
    model.shift_drift(5.0)
    np.testing.assert_allclose(model.predict_drift(rec), before + 5.0, atol=1e-9)


def test_temperature_dlstm_reference_is_read_on_the_training_run_not_at_rate_zero() -> None:
    """Issue 22 item 7: the single ramp never shows the network a rate of 0, so its reference is
    where the training run passes T_ref: there its relative estimate is zero, whatever it says
    with the temperature held."""
    torch.manual_seed(0)
    n = 1200
    temp = np.linspace(-10.0, 50.0, n)  # one ramp, as the paper's experiment
    accel = GRAVITY_MG + cubic_drift(temp) + np.random.default_rng(1).normal(0.0, 0.2, n)
    rec = Recording(
        {"time_s": np.arange(n) / RATE_HZ, "temp_c": temp, "accel_mg": accel},
        {"sample_rate_hz": str(RATE_HZ)},
        "ramp.csv",
    )
    settings = FusionSettings(population=1, iterations=20, cycles=0)
    model = fit_compensator("dlstm-temp", rec, {"settings": settings, "progress": False})
    assert model.offset is not None and model.offset.t_ref_c == pytest.approx(20.0)
    estimate = model.predict_drift(rec)
    near = np.abs(temp - 20.0) <= 0.5  # the ramp's samples at T_ref, averaged by hand
    assert float(np.mean(estimate[near])) == pytest.approx(0.0, abs=0.2)  # the old reading: 15 mg


def test_recursive_methods_have_no_reference() -> None:
    model = fit_compensator("persistence", static_run(GRAVITY_MG))
    assert model.offset is None


def test_relative_scoring_uses_the_true_drift_relative_to_t_ref() -> None:
    rec = static_run(GRAVITY_MG)
    t_ref = 20.0
    relative_estimate = cubic_drift(rec.temp_c) - cubic_drift(np.array(t_ref))
    compensated = rec.accel_mg - relative_estimate
    relative = drift_score(rec, compensated, t_ref)
    absolute = drift_score(rec, compensated)
    assert relative is not None and absolute is not None
    assert relative.residual_rms_mg < 0.05
    assert absolute.residual_rms_mg == pytest.approx(float(cubic_drift(np.array(t_ref))), rel=0.02)


@pytest.fixture(scope="module")
def gravity_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("offset") / "static.csv"
    write_recording(static_run(GRAVITY_MG).without_truth(), path)
    return path


def test_fit_prints_the_constant_and_keeps_it_in_the_checkpoint(
    gravity_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "p.pt"
    assert main(["fit", "--method", "poly3", str(gravity_csv), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "constant removed 0 mg" in printed and "T_ref 20.00 degC" in printed
    model, checkpoint = load_model(out)
    assert OffsetRecord.from_dict(checkpoint["offset"]) == model.offset
    assert model.offset is not None and model.offset.drift_at_t_ref_mg < -900


@pytest.mark.parametrize("method", ["poly3", "poly1", "pla"])
def test_a_fit_at_the_users_tref_is_a_model_every_command_reads(
    method: str, gravity_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The cubic is re-expanded about ``--tref`` (its own T_ref was the range mid-point, and the
    file, holding two, was refused as damaged by every command after the fit)."""
    default, moved = tmp_path / "d.pt", tmp_path / "m.pt"
    assert main(["fit", "--method", method, str(gravity_csv), "-o", str(default), "--quiet"]) == 0
    assert (
        main(["fit", "--method", method, "--tref", "5", str(gravity_csv), "-o", str(moved), "--quiet"]) == 0
    )
    (at_mid, _), (at_five, checkpoint) = load_model(default), load_model(moved)
    assert checkpoint["offset"]["t_ref_c"] == 5.0
    if "t_ref_c" in checkpoint["payload"]:
        assert checkpoint["payload"]["t_ref_c"] == 5.0
    # the same fitted curve, zero at 5 degC instead of at the mid-point (20 degC)
    temp = np.linspace(-10.0, 50.0, 61)
    curve = at_mid.drift_at(temp)  # type: ignore[attr-defined]
    np.testing.assert_allclose(
        at_five.drift_at(temp),  # type: ignore[attr-defined]
        curve - at_mid.drift_at(np.array([5.0]))[0],  # type: ignore[attr-defined]
        atol=1e-9 * float(np.max(np.abs(curve))),
    )
    assert main(["evaluate", str(moved), str(gravity_csv)]) == 0
    assert codegen_main(["export", str(moved), "-o", str(tmp_path / "c")]) == 0
    assert "drift relative to T_ref 5.00 degC" in capsys.readouterr().out


def test_fit_refuses_gravity_as_an_absolute_constant(
    gravity_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "p.pt"
    argv = ["fit", "--method", "pla", str(gravity_csv), "-o", str(out), "--offset", "absolute"]
    assert run_cli(main, argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "--offset absolute-unbounded" in lines[0]
    assert not out.exists()


def test_export_prints_the_constant_and_says_it_in_the_header(
    gravity_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = tmp_path / "p.pt"
    assert main(["fit", "--method", "poly3", str(gravity_csv), "-o", str(model)]) == 0
    capsys.readouterr()
    assert codegen_main(["export", str(model), "-o", str(tmp_path / "c")]) == 0
    assert "constant removed 0 mg" in capsys.readouterr().out
    header = (tmp_path / "c" / "tdc_poly3.h").read_text()
    assert "offset: drift relative to T_ref 20.00 degC, constant removed 0 mg" in header


def test_export_of_a_recursive_method_warns_about_sustained_inputs(
    gravity_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    small = ["--population", "1", "--iterations", "2", "--cycles", "0", "--quiet"]
    assert main(["fit", "--method", "dlstm", str(gravity_csv), "-o", str(tmp_path / "d.pt"), *small]) == 0
    assert "removes any sustained acceleration" in capsys.readouterr().out
    model = tmp_path / "m.pt"
    rec = read_recording(gravity_csv)
    save_model(
        fit_compensator("persistence", rec), model, train_stats=TrainStats(), valid_temp_range_c=(-10.0, 50.0)
    )
    assert codegen_main(["export", str(model), "-o", str(tmp_path / "c")]) == 0
    assert "removes any sustained acceleration" in capsys.readouterr().out
    header = " ".join((tmp_path / "c" / "tdc_persistence.h").read_text().replace("*", " ").split())
    assert "recursive method: it learns from the past output and removes any sustained acceleration" in header


def test_export_warns_about_an_older_model_that_removes_gravity(
    gravity_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A checkpoint without an offset record removes its fitted constant: export measures it and
    warns above 100 mg (fit, where the option lives, is what refuses)."""
    model = tmp_path / "old.pt"
    argv = ["fit", "--method", "poly3", str(gravity_csv), "-o", str(model), "--offset", "absolute-unbounded"]
    assert main(argv) == 0
    checkpoint = load_checkpoint(model)
    del checkpoint["offset"]
    torch.save(checkpoint, model)
    capsys.readouterr()
    assert codegen_main(["export", str(model), "-o", str(tmp_path / "c")]) == 0
    printed = capsys.readouterr().out
    expected = GRAVITY_MG + float(cubic_drift(np.array(20.0)))
    constant = float(printed.split("fitted constant, ")[1].split(" mg")[0])
    assert constant == pytest.approx(expected, abs=0.5)
    assert "WARNING: above 100 mg" in printed and "--offset relative" in printed
    assert "WARNING: above 100 mg" in (tmp_path / "c" / "tdc_poly3.h").read_text()
