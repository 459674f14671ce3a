"""A model fitted with ``--holdout`` keeps its held-out score, and one worse than none there is not exported.

The recording: a chamber cycle whose drift is +k (T - 25) in its first half and -k (T - 25) in its
second (a loop that flips). A cubic fitted on the first half removes +k (T - 25) from the second,
which leaves 2k (T - 25): twice no compensation's drift, held out. ``fit`` must say so, keep the
figures (the same ``trainer evaluate --holdout`` prints) and ``codegen export`` must refuse the
model in one line, writing nothing, whatever the format; the same fit on a run without the flip
exports.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from trainer.checkpoint import load_checkpoint
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import run_cli

RATE_HZ = 2.0
K_MG_PER_C = 0.3


def _run(path: Path, *, flip: bool) -> Path:
    t = np.arange(0.0, 8000.0, 1.0 / RATE_HZ)
    temp = 25.0 + 30.0 * np.sin(2.0 * np.pi * t / 4000.0)  # two cycles, -5..55 degC
    sign = np.where(t < t[-1] / 2.0, 1.0, -1.0) if flip else np.ones_like(t)
    noise = np.random.default_rng(5).normal(0.0, 0.05, t.size)
    accel = 1000.0 + sign * K_MG_PER_C * (temp - 25.0) + noise
    write_recording(
        Recording(
            {"time_s": t, "temp_c": temp, "accel_mg": accel}, {"sample_rate_hz": repr(RATE_HZ)}, path.name
        ),
        path,
    )
    return path


def _fit(rec: Path, model: Path, capsys: pytest.CaptureFixture[str]) -> str:
    capsys.readouterr()
    argv = ["fit", "--method", "poly3", str(rec), "--holdout", "last:0.5", "-o", str(model)]
    assert run_cli(trainer_main, argv) == 0
    return capsys.readouterr().out


def test_a_model_worse_than_none_held_out_is_refused_by_every_export(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec, model = _run(tmp_path / "flip.csv", flip=True), tmp_path / "flip.pt"
    out = _fit(rec, model, capsys)
    assert (
        "worse than uncompensated: held-out part (--holdout last:0.5 " in out
        and "codegen export refuses" in out
    )
    record = load_checkpoint(model)["train_stats"]["held_out"]
    assert record["holdout"] == "last:0.5"
    # the held-out drift is twice no compensation's, of the same shape: the model leaves about 2x
    assert record["model_rms"] == pytest.approx(2.0 * record["uncompensated_rms"], rel=0.1)
    # the same figures trainer evaluate --holdout prints for the model
    capsys.readouterr()
    argv = ["evaluate", str(model), str(rec), "--holdout", "last:0.5", "--out-dir", str(tmp_path / "ev")]
    assert run_cli(trainer_main, argv) == 0
    evaluated = capsys.readouterr().out
    found = re.search(
        r"drift left, deviation from a constant \[poly3\]: RMS (\S+) mg \(uncompensated (\S+) mg\)", evaluated
    )
    # and evaluate warns with the sign-off guard's words, as fit did
    assert (
        "warning [poly3]: it leaves more drift than no compensation here: worse than uncompensated"
        in evaluated
    )
    assert found is not None
    assert (f"{record['model_rms']:.4g}", f"{record['uncompensated_rms']:.4g}") == found.groups()
    for extra in ([], ["--format", "px4-params"], ["--format", "ardupilot-parm"]):
        target = tmp_path / f"out{len(extra)}{extra[-1] if extra else ''}"
        capsys.readouterr()
        assert run_cli(codegen_main, ["export", str(model), "-o", str(target), *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "must not reach firmware" in err and str(model) in err, err
        assert not target.exists()


def test_the_same_fit_without_the_flip_exports(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec, model = _run(tmp_path / "same.csv", flip=False), tmp_path / "same.pt"
    out = _fit(rec, model, capsys)
    assert "better than uncompensated: held-out part (--holdout last:0.5 " in out
    record = load_checkpoint(model)["train_stats"]["held_out"]
    assert record["model_rms"] < 0.1 * record["uncompensated_rms"]
    assert run_cli(codegen_main, ["export", str(model), "-o", str(tmp_path / "c"), "--name", "same"]) == 0
    assert (tmp_path / "c" / "same.h").is_file()


@pytest.mark.parametrize(
    ("key", "value"), [("model_rms", "small"), ("model_rms", -1.0), ("uncompensated_rms", None)]
)
def test_a_hand_edited_held_out_record_is_named_not_judged(
    key: str, value: object, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A figure of text, a negative RMS or no uncompensated figure would make the guard's comparison
    meaningless and could let the model through: the file is refused on loading, in one line naming
    the field."""
    import torch

    rec, model = _run(tmp_path / "flip.csv", flip=True), tmp_path / "flip.pt"
    _fit(rec, model, capsys)
    checkpoint = torch.load(model, weights_only=True)
    checkpoint["train_stats"]["held_out"][key] = value
    torch.save(checkpoint, model)
    capsys.readouterr()
    assert run_cli(codegen_main, ["export", str(model), "-o", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "train_stats.held_out" in err, err
    assert not (tmp_path / "c").exists()


def test_the_sign_off_of_its_training_run_judges_the_part_its_fit_held_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Reported on its own run without --holdout, the model's whole-run figures are mostly in-sample
    and look better than none; the verdict judges the part the fit held out, as export does."""
    rec, model = _run(tmp_path / "flip.csv", flip=True), tmp_path / "flip.pt"
    _fit(rec, model, capsys)
    argv = ["report", str(model), "--recording", str(rec), "-o", str(tmp_path / "rep")]
    assert run_cli(trainer_main, argv) == 1
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "## Verdict: FAIL" in text
    assert "worse than uncompensated: held-out part (--holdout last:0.5 of the training run" in text


def test_evaluate_prints_the_in_range_figure_fit_recorded(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A held-out part partly beyond the trained range (30 -> 60 degC after training up to 50): the
    figure inside the range is what export also judges; evaluate prints it, equal to fit's record."""
    t = np.arange(0.0, 8000.0, 1.0 / RATE_HZ)
    temp = np.interp(t / t[-1], [0.0, 0.5, 0.7, 1.0], [0.0, 50.0, 30.0, 60.0])
    accel = 1000.0 + 0.01 * (temp - 25.0) ** 2 + np.random.default_rng(6).normal(0.0, 0.05, t.size)
    rec, model = tmp_path / "beyond.csv", tmp_path / "beyond.pt"
    columns = {"time_s": t, "temp_c": temp, "accel_mg": accel}
    write_recording(Recording(columns, {"sample_rate_hz": repr(RATE_HZ)}, "beyond"), rec)
    argv = ["fit", "--method", "poly3", str(rec), "--holdout", "last:0.3", "-o", str(model)]
    assert run_cli(trainer_main, argv) == 0
    record = load_checkpoint(model)["train_stats"]["held_out"]
    assert record["model_in_range_rms"] is not None
    capsys.readouterr()
    argv = ["evaluate", str(model), str(rec), "--holdout", "last:0.3", "--out-dir", str(tmp_path / "ev")]
    assert run_cli(trainer_main, argv) == 0
    out = capsys.readouterr().out
    expected = (
        f"drift left inside the trained range [poly3]: RMS {record['model_in_range_rms']:.4g} mg "
        f"(uncompensated {record['uncompensated_in_range_rms']:.4g} mg)"
    )
    assert expected in out, out
