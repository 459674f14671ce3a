"""The foundation's commands end to end: simulate -> fit -> evaluate, and their error behaviour."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.cli_capture import run_captured
from trainer.checkpoint import load_model
from trainer.cli import main
from trainer.data.recording_io import read_recording
from trainer.methods import name_of


def _process(*args: str) -> tuple[int, str]:
    """Run the real entry point in a fresh interpreter, as a user would (exit code, stderr)."""
    done = subprocess.run(
        [sys.executable, "-m", "trainer.cli", *args], capture_output=True, text=True, timeout=300
    )
    return done.returncode, done.stderr


def _in_process(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    """The entry point's ``run_cli(main)`` in this interpreter (no start-up): exit code, stderr."""
    code, _, err = run_captured(main, capsys, *args)
    return code, err


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A short training and validation run of the paper protocol (compressed to 20 min at 50 Hz)."""
    work = tmp_path_factory.mktemp("pipeline")
    paths = []
    for name, seed in (("train", 1), ("valid", 2)):
        path = work / f"{name}.npz"
        assert (
            main(
                [
                    "simulate",
                    "--protocol",
                    "paper-oven",
                    "--seed",
                    str(seed),
                    "--duration",
                    "1200",
                    "--rate",
                    "50",
                    "-o",
                    str(path),
                ]
            )
            == 0
        )
        paths.append(path)
    return paths[0], paths[1]


@pytest.mark.parametrize("method", ["pla", "poly3"])
def test_fit_then_evaluate_removes_most_of_the_true_drift(
    recordings: tuple[Path, Path], tmp_path: Path, method: str, capsys: pytest.CaptureFixture[str]
) -> None:
    train, valid = recordings
    model_path = tmp_path / f"{method}.pt"
    assert main(["fit", "--method", method, str(train), "-o", str(model_path)]) == 0
    model, checkpoint = load_model(model_path)
    rec = read_recording(train)
    assert checkpoint["valid_temp_range_c"] == [
        pytest.approx(rec.temp_c.min()),
        pytest.approx(rec.temp_c.max()),
    ]
    assert checkpoint["train_stats"]["n_samples"] == len(rec)

    out_dir = tmp_path / "eval"
    capsys.readouterr()
    assert main(["evaluate", str(model_path), str(valid), "--out-dir", str(out_dir)]) == 0
    printed = capsys.readouterr().out
    for row in ("B (mg)", "K (mg/s^1/2)", "R (mg/s)", "Aver (%)"):
        assert row in printed
    for name in ("report.md", "fig12_compensated.png", "fig13_allan.png"):
        assert (out_dir / name).stat().st_size > 0
    # Independent check of the headline metric: compensation must remove most of the true drift.
    # The model is relative to T_ref (the default offset policy): so is the truth it is scored on.
    validation = read_recording(valid)
    true_drift = validation.truth("drift_mg")
    assert model.offset is not None and model.offset.relative
    t_ref = 0.5 * (rec.temp_c.min() + rec.temp_c.max())
    assert model.offset.t_ref_c == pytest.approx(t_ref)
    near = np.abs(validation.temp_c - t_ref) < 0.5
    true_relative = true_drift - np.mean(true_drift[near])
    residual = true_relative - model.predict_drift(validation.without_truth())
    raw_rms = np.sqrt(np.mean(true_relative**2))
    assert np.sqrt(np.mean(residual**2)) < 0.1 * raw_rms
    assert f"residual drift vs true_drift_mg relative to T_ref {t_ref:.2f} degC" in printed


def test_fit_never_reads_ground_truth(recordings: tuple[Path, Path], tmp_path: Path) -> None:
    train, _ = recordings
    rec = read_recording(train)
    rec.columns["true_drift_mg"] = rec.columns["true_drift_mg"] * 0 + 1e6  # poison the truth
    from trainer.data.recording_io import write_recording

    poisoned = tmp_path / "poisoned.npz"
    write_recording(rec, poisoned)
    for path, name in ((train, "a.pt"), (poisoned, "b.pt")):
        assert main(["fit", "--method", "pla", str(path), "-o", str(tmp_path / name)]) == 0
    a, _ = load_model(tmp_path / "a.pt")
    b, _ = load_model(tmp_path / "b.pt")
    np.testing.assert_array_equal(a.slopes_mg_per_c, b.slopes_mg_per_c)


def _assert_clean_failure(result: tuple[int, str], *fragments: str) -> None:
    code, stderr = result
    assert code == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    assert "Traceback" not in stderr
    for fragment in fragments:
        assert fragment in lines[0]


def test_fit_missing_recording(tmp_path: Path) -> None:
    out = tmp_path / "m.pt"
    _assert_clean_failure(
        _process("fit", "--method", "pla", str(tmp_path / "nope.csv"), "-o", str(out)), "nope.csv"
    )
    assert not out.exists()


def test_fit_bad_recording_leaves_no_model(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,temp_c,accel_mg\n0.0,20.0,1.0\n0.005,abc,1.0\n")
    out = tmp_path / "m.pt"
    _assert_clean_failure(
        _in_process(capsys, "fit", "--method", "poly3", str(bad), "-o", str(out)), "bad.csv", "temp_c"
    )
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [bad]


def test_fit_unknown_method_is_a_usage_error(tmp_path: Path) -> None:
    _assert_clean_failure(
        _process("fit", "--method", "magic", "x.csv", "-o", str(tmp_path / "m.pt")), "--method"
    )


def test_evaluate_rejects_a_foreign_model_file(
    recordings: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    fake = tmp_path / "model.pt"
    fake.write_bytes(b"this is not a checkpoint")
    out_dir = tmp_path / "eval"
    _assert_clean_failure(
        _in_process(capsys, "evaluate", str(fake), str(recordings[1]), "--out-dir", str(out_dir)), "model.pt"
    )
    assert not out_dir.exists()


def test_evaluate_negative_smoothing_is_rejected(
    recordings: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = tmp_path / "m.pt"
    assert main(["fit", "--method", "pla", str(recordings[0]), "-o", str(model)]) == 0
    _assert_clean_failure(
        _in_process(capsys, "evaluate", str(model), str(recordings[1]), "--smoothing", "-1"), "--smoothing"
    )


@pytest.fixture(scope="module")
def steps(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An input-test recording: the tilt-sequence true input on the same short protocol."""
    path = tmp_path_factory.mktemp("input") / "steps.npz"
    args = [
        "simulate",
        "--seed",
        "5",
        "--duration",
        "1200",
        "--rate",
        "50",
        "--input",
        "steps",
        "-o",
        str(path),
    ]
    assert main(args) == 0
    return path


def test_compare_writes_the_table_figures_report_and_models(
    recordings: tuple[Path, Path], steps: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    train, valid = recordings
    out_dir = tmp_path / "cmp"
    (tmp_path / "cmp").mkdir()
    keep = out_dir / "notes.txt"
    keep.write_text("mine")
    args = ["compare", str(train), str(valid), "--out-dir", str(out_dir), "--input-test", str(steps)]
    args += ["--population", "2", "--iterations", "5", "--cycles", "3", "--quiet"]
    capsys.readouterr()
    assert main(args) == 0
    printed = capsys.readouterr().out
    for method in ("dlstm", "dlstm-ssa", "dlstm-issa", "pla", "poly3", "dlstm-temp", "persistence", "oracle"):
        assert f"| {method} |" in printed
    for name in (
        "report.md",
        "table1.txt",
        "fig10_training_fit.png",
        "fig11_validation_fit.png",
        "fig12_compensated.png",
        "fig13_allan.png",
        "fig_input_survival_1_steps.png",
    ):
        assert (out_dir / name).stat().st_size > 0, name
    for method in ("dlstm", "dlstm-ssa", "dlstm-issa", "pla", "poly3", "dlstm-temp", "persistence"):
        model, _ = load_model(out_dir / "models" / f"{method}.pt")
        assert name_of(model) == method
    assert keep.read_text() == "mine"  # an existing output directory keeps the user's files
    report = (out_dir / "report.md").read_text()
    assert "persistence" in report and "oracle" in report and "How to read the scores" in report


def test_compare_survival_separates_temperature_models_from_recursive_ones(
    recordings: tuple[Path, Path], steps: Path
) -> None:
    """Independent physics check: a temperature-only model cannot remove a true input step."""
    from trainer.dlstm.fusion import FusionSettings
    from trainer.scoring.compare import compare

    train, valid = recordings
    result = compare(
        read_recording(train),
        read_recording(valid),
        FusionSettings(population=2, iterations=5, cycles=2),
        input_tests=(read_recording(steps),),
        methods=("pla", "poly3", "persistence"),
        progress=False,
        log=lambda _: None,
    )
    scores = next(iter(result.survival.values()))
    assert scores["pla"].gain == pytest.approx(1.0, abs=0.02)
    assert scores["poly3"].gain == pytest.approx(1.0, abs=0.02)
    assert scores["oracle"].gain == pytest.approx(1.0, abs=2e-3)  # noise correlates by chance only
    assert scores["persistence"].gain < 0.05


def test_fit_dlstm_from_the_cli(recordings: tuple[Path, Path], tmp_path: Path) -> None:
    out = tmp_path / "issa.pt"
    assert (
        main(
            [
                "fit",
                "--method",
                "dlstm-issa",
                str(recordings[0]),
                "-o",
                str(out),
                "--population",
                "2",
                "--iterations",
                "3",
                "--cycles",
                "2",
                "--quiet",
            ]
        )
        == 0
    )
    _, checkpoint = load_model(out)
    assert checkpoint["payload"]["training"]["settings"]["population"] == 2
    assert checkpoint["payload"]["frontend"]["decimation"] == 50  # 1 s steps at 50 Hz
    # The same inputs give the same bytes (so the same model id in the generated C): the
    # checkpoint holds no wall-clock time. Fitted again into the same path, it must not change.
    first = out.read_bytes()
    args = ["--population", "2", "--iterations", "3", "--cycles", "2", "--quiet"]
    assert main(["fit", "--method", "dlstm-issa", str(recordings[0]), "-o", str(out), *args]) == 0
    assert out.read_bytes() == first


def test_fit_dlstm_rejects_bad_settings(
    recordings: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    result = _in_process(
        capsys,
        "fit",
        "--method",
        "dlstm",
        str(recordings[0]),
        "-o",
        str(tmp_path / "m.pt"),
        "--population",
        "0",
    )
    _assert_clean_failure(result, "--population")
