"""A path of the wrong kind (a device as the model, a directory as the recording) is one line that
says what it is, not "no such file" about a file that exists or an "extension '(none)'"."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.testmodels import baseline_checkpoint, save_checkpoint
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import run_cli


@pytest.fixture
def files(tmp_path: Path) -> tuple[Path, Path]:
    temp = np.linspace(-10.0, 40.0, 200)
    rec = Recording(
        {"time_s": np.arange(temp.size, dtype=float), "temp_c": temp, "accel_mg": 0.1 * temp},
        {"sample_rate_hz": "1"},
        "paths",
    )
    recording = tmp_path / "run.csv"
    write_recording(rec, recording)
    model = tmp_path / "m.pt"
    save_checkpoint(baseline_checkpoint("poly3", rec), model)
    return model, recording


@pytest.mark.parametrize(
    ("which", "expected"),
    [
        ("model is a device", "/dev/null: not a regular file (a device or a pipe)"),
        ("recording is a directory", ": a directory, not a recording (.csv or .npz)"),
    ],
)
def test_a_path_of_the_wrong_kind_says_what_it_is(
    which: str, expected: str, files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model, recording = files
    args = ["/dev/null", str(recording)] if which == "model is a device" else [str(model), str(tmp_path)]
    code = run_cli(trainer_main, ["evaluate", *args])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert expected in err and "no such" not in err and "(none)" not in err, err


def test_a_directory_as_the_training_recording_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = run_cli(trainer_main, ["fit", "--method", "poly3", str(tmp_path), "-o", str(tmp_path / "m.pt")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.endswith("a directory, not a recording (.csv or .npz)"), err
    assert not (tmp_path / "m.pt").exists()


def test_import_says_what_a_model_or_a_recording_of_this_tool_is(
    files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``trainer import m.pt`` and ``trainer import run.csv`` (a recording this tool wrote) said
    "--temp COLUMN is required"; with its columns mapped a recording is imported again (to resample it)."""
    model, recording = files
    for given, expected in (
        (model, f"{model}: a model file (.pt) where a logger's file or a flight log is expected"),
        (recording, f"{recording}: already a recording of this tool's format"),
    ):
        assert run_cli(trainer_main, ["import", str(given), "-o", str(tmp_path / "out.csv")]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"error: {expected}") and err.count("\n") == 1, err
        assert not (tmp_path / "out.csv").exists()
    mapped = ["--time", "time_s", "--temp", "temp_c", "--accel", "accel_mg", "--accel-unit", "mg"]
    assert run_cli(trainer_main, ["import", str(recording), *mapped, "-o", str(tmp_path / "again.csv")]) == 0
