"""``trainer fit --method`` takes auto's candidates that are a registered method with fixed options
(``poly1``, ``physics-branches``, ...), and ``--holdout`` trains on the part a split leaves: what
auto would ship can be fitted on any part of a run and scored on the rest with ``trainer evaluate
--holdout``, the cross-check a user asks of a candidate auto chose."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.cli_corpus import valid_lines
from trainer.checkpoint import load_model
from trainer.cli import main as trainer_main
from trainer.data.recording_io import read_recording
from trainer.errors import run_cli
from trainer.selection import CANDIDATES, variant_labels


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    path = tmp_path / "rec.csv"
    path.write_text("\n".join(valid_lines()) + "\n")
    return path


def test_every_candidate_auto_can_ship_is_a_fit_method() -> None:
    """Each candidate except no compensation is fittable by name: a registered method or a variant."""
    from trainer import methods

    fittable = {*methods.fit_cli_names(), *variant_labels()}
    assert {c.label for c in CANDIDATES if c.label != "none"} <= fittable
    assert "physics-branches" in variant_labels() and "poly3" not in variant_labels()


def test_poly1_is_a_straight_line_in_temperature(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "m.pt"
    assert run_cli(trainer_main, ["fit", "--method", "poly1", str(recording), "-o", str(out), "--quiet"]) == 0
    # the summary names the method asked for, not the registered one that loads it (it said poly3)
    summary = capsys.readouterr().out.splitlines()
    assert summary[0].startswith("poly1: fitted on") and not any(line.startswith("poly3") for line in summary)
    model, _ = load_model(out)
    rec = read_recording(recording)
    temp = np.asarray(rec.temp_c, dtype=np.float64)
    drift = model.predict_drift(rec)
    slope, _ = np.polyfit(temp, drift, 1)
    assert np.max(np.abs(drift - np.polyval(np.polyfit(temp, drift, 1), temp))) < 1e-9 * np.ptp(drift)
    # the least-squares slope of the data (0.1 mg/degC plus the cubic's linear share), within 5 %
    assert slope == pytest.approx(np.polyfit(temp, np.asarray(rec.accel_mg), 1)[0], rel=0.05)


def test_a_variant_model_is_named_as_fitted_by_every_command_that_reads_it(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The model file records the variant (its registered method alone, ``poly3``, misnamed it in
    ``trainer evaluate`` and the exported module's header)."""
    from codegen.cli import main as codegen_main

    out = tmp_path / "m.pt"
    assert run_cli(trainer_main, ["fit", "--method", "poly1", str(recording), "-o", str(out), "--quiet"]) == 0
    _, checkpoint = load_model(out)
    assert checkpoint["method"] == "poly3" and checkpoint["train_stats"]["variant"] == "poly1"
    capsys.readouterr()
    assert run_cli(trainer_main, ["evaluate", str(out), str(recording)]) == 0
    header = next(line for line in capsys.readouterr().out.splitlines() if "Validation Data" in line)
    assert header.split()[2] == "poly1"
    assert run_cli(codegen_main, ["export", str(out), "-o", str(tmp_path / "c")]) == 0
    source = next((tmp_path / "c").glob("*.c")).read_text()
    assert 'method "poly1"' in source and 'method "poly3"' not in source


def test_a_physics_variant_fits_its_fixed_effect_and_says_who_fixed_it(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "m.pt"
    argv = ["fit", "--method", "physics-branch-room", str(recording), "-o", str(out), "--quiet"]
    assert run_cli(trainer_main, argv) == 0
    printed = capsys.readouterr().out
    assert "forced: hysteresis_offset (method physics-branch-room)" in printed
    _, checkpoint = load_model(out)
    assert checkpoint["method"] == "physics"


@pytest.mark.parametrize(
    ("option", "name"),
    [
        (["--effects", "thermal_lag"], "--effects"),
        (["--from-sim", "a.toml"], "--from-sim"),
        (["--warmup"], "--warmup"),
    ],
)
def test_an_option_a_variant_fixes_is_refused_in_one_line(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], option: list[str], name: str
) -> None:
    out = tmp_path / "m.pt"
    code = run_cli(
        trainer_main, ["fit", "--method", "physics-branches", *option, str(recording), "-o", str(out)]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and not out.exists()
    assert f"{name} does not apply to --method physics-branches: it fixes effects hysteresis_offset" in err


def test_holdout_trains_on_the_part_it_leaves(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "m.pt"
    argv = ["fit", "--method", "poly3", "--holdout", "first:0.25", str(recording), "-o", str(out), "--quiet"]
    assert run_cli(trainer_main, argv) == 0
    _, checkpoint = load_model(out)
    rec = read_recording(recording)
    first_trained = rec.time_s[round(0.25 * len(rec))]
    assert checkpoint["train_stats"]["time_range_s"] == [
        pytest.approx(first_trained),
        pytest.approx(rec.time_s[-1]),
    ]
    assert checkpoint["train_stats"]["n_samples"] == len(rec) - round(0.25 * len(rec))
    capsys.readouterr()
    # the held-out part is not training data; the other side of the split is
    ev = ["evaluate", str(out), str(recording), "--out-dir"]
    assert run_cli(trainer_main, [*ev, str(tmp_path / "a"), "--holdout", "first:0.25"]) == 0
    assert "in-sample" not in "".join(capsys.readouterr())
    assert run_cli(trainer_main, [*ev, str(tmp_path / "b"), "--holdout", "last:0.5"]) == 0
    assert "are training rows" in "".join(capsys.readouterr())


def test_a_bad_holdout_is_one_line_before_any_reading(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "m.pt"
    argv = [
        "fit",
        "--method",
        "poly3",
        "--holdout",
        "first:1.5",
        str(tmp_path / "missing.csv"),
        "-o",
        str(out),
    ]
    assert run_cli(trainer_main, argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--holdout" in err and "missing.csv" not in err and not out.exists()
