"""``trainer report``: the sign-off document's pass/fail follows the thresholds, its numbers are the
static drift-left scores, and a bad thresholds file is a one-line error with no output."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from trainer.checkpoint import load_model
from trainer.cli import main as trainer_main
from trainer.data.recording_io import read_recording
from trainer.errors import run_cli

SMOOTHING_S = 0.5


@pytest.fixture(scope="module")
def unit(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 4-minute simulated oven run at 20 Hz, a cubic fitted on it and its C module."""
    folder = tmp_path_factory.mktemp("unit")
    rec, model, module = folder / "rec.npz", folder / "poly3.pt", folder / "module"
    sim = ["simulate", "--seed", "3", "--duration", "240", "--rate", "20", "-o", str(rec)]
    assert trainer_main(sim) == 0
    assert trainer_main(["fit", "--method", "poly3", str(rec), "-o", str(model)]) == 0
    assert run_cli(codegen_main, ["export", str(model), "-o", str(module), "--name", "u_poly3"]) == 0
    return {"rec": rec, "model": model, "module": module, "folder": folder}


def _measured_rms_and_max(unit: dict[str, Path]) -> tuple[float, float]:
    """Independently: the compensated output, trailing 0.5 s mean, about its mean."""
    rec = read_recording(unit["rec"])
    model, _ = load_model(unit["model"])
    out = model.compensate(rec.without_truth())
    n = round(SMOOTHING_S * rec.sample_rate_hz)
    csum = np.concatenate(([0.0], np.cumsum(out)))
    k = np.arange(out.size)
    lo = np.maximum(0, k - n + 1)
    smoothed = (csum[k + 1] - csum[lo]) / (k + 1 - lo)
    left = smoothed - smoothed.mean()
    return float(np.sqrt(np.mean(left**2))), float(np.max(np.abs(left)))


def _report(unit: dict[str, Path], out: Path, config: str | None, *extra: str) -> int:
    args = ["report", str(unit["model"]), "--recording", str(unit["rec"]), "-o", str(out), *extra]
    if config is not None:
        path = out.parent / f"{out.name}.toml"
        path.write_text(config)
        args += ["--config", str(path)]
    return run_cli(trainer_main, args)


def test_pass_and_fail_follow_the_thresholds(unit: dict[str, Path], tmp_path: Path) -> None:
    rms, peak = _measured_rms_and_max(unit)
    above = f"[thresholds]\nresidual_rms_mg = {rms * 1.001}\nresidual_max_mg = {peak * 1.001}\n"
    above += "max_verify_mismatches = 0\nmin_coverage = 1.0\n"
    assert _report(unit, tmp_path / "pass", above, "--verify", str(unit["module"])) == 0
    text = (tmp_path / "pass" / "report.md").read_text()
    assert "## Verdict: PASS" in text and "0 mismatches" in text and "FAIL" not in text
    assert f"{rms:.4g}" in text and f"{peak:.4g}" in text
    figures = sorted(p.name for p in (tmp_path / "pass").glob("*.png"))
    assert len(figures) == 2 and figures[0].endswith("_drift.png") and figures[1].endswith("_residual.png")
    assert all(f"]({name})" in text for name in figures)
    for key, value in (("residual_rms_mg", rms), ("residual_max_mg", peak)):
        below = f"[thresholds]\n{key} = {value * 0.999}\n"
        assert _report(unit, tmp_path / f"fail-{key}", below) == 1
        text = (tmp_path / f"fail-{key}" / "report.md").read_text()
        assert "## Verdict: FAIL" in text and f"`{key}`" in text


def test_a_threshold_without_its_measurement_fails_as_not_measured(
    unit: dict[str, Path], tmp_path: Path
) -> None:
    assert _report(unit, tmp_path / "r", "[thresholds]\nmax_instructions_per_sample = 1000\n") == 1
    text = (tmp_path / "r" / "report.md").read_text()
    assert "| not measured |" in text and "## Verdict: FAIL" in text
    other = tmp_path / "other.json"  # a clean verify result, but of another model: not this one's
    other.write_text('{"mismatches": 0, "samples": 9, "state_equal": true, "model_id": "sha256:00"}')
    config = "[thresholds]\nmax_verify_mismatches = 0\n"
    assert _report(unit, tmp_path / "v", config, "--verify", str(other)) == 1
    text = (tmp_path / "v" / "report.md").read_text()
    assert "| not measured |" in text and "WARNING: the module is of model sha256:00" in text


@pytest.mark.parametrize(
    ("config", "message"),
    [
        ("[thresholds]\nresidual_rms = 1.0\n", "unknown key 'residual_rms'"),
        ("[thresholds]\nresidual_rms_mg = 'small'\n", "residual_rms_mg must be a number"),
        ("[limits]\nresidual_rms_mg = 1.0\n", "unknown table or key 'limits'"),
        ("[thresholds\n", "not valid TOML"),
    ],
)
def test_a_bad_thresholds_file_is_one_line_and_writes_nothing(
    config: str, message: str, unit: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert _report(unit, tmp_path / "never", config) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "never.toml" in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "never").exists()
