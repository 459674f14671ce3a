"""The golden model against the trainer's float models: the error budget, the cell state's precision
over a 2 h stream, the documented saturation of the cell state, and (slow) the full verify."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from codegen import testmodels as tm
from codegen.cli import main as codegen_main
from codegen.export import export
from codegen.golden import golden_for
from codegen.hostbuild import load_module
from codegen.quantize import ACCEL_PER_MG, FLAG_SATURATED
from codegen.verify import integer_recording, to_step_units
from trainer.checkpoint import load_model
from trainer.cli import main as trainer_main
from trainer.recording import Recording
from trainer.recording_io import read_recording

# Documented budget of the integer arithmetic alone (golden minus float on the same integer inputs),
# in mg: far below the simulated sensor's 0.35 mg white noise per sample.
ARITHMETIC_RMS_MG = {"dlstm": 5e-4, "dlstm-temp": 5e-4, "persistence": 5e-5, "pla": 5e-5, "poly3": 5e-5}
ARITHMETIC_MAX_MG = {"dlstm": 3e-3, "dlstm-temp": 3e-3, "persistence": 1e-4, "pla": 1e-4, "poly3": 1e-4}


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Recording:
    path = tmp_path_factory.mktemp("rec") / "short.npz"
    assert trainer_main(["simulate", "--seed", "4", "--duration", "600", "-o", str(path)]) == 0
    return read_recording(path)


def _save(checkpoint: dict[str, Any], directory: Path) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / "model.pt"
    tm.save_checkpoint(checkpoint, path)
    return path


def _checkpoint(method: str, rec: Recording) -> dict[str, Any]:
    if method in ("pla", "poly3"):
        return tm.baseline_checkpoint(method, rec)
    if method == "persistence":
        return tm.persistence_checkpoint(rec)
    return tm.dlstm_checkpoint(method, rec, seed=11)


@pytest.mark.parametrize("method", sorted(ARITHMETIC_RMS_MG))
def test_golden_against_the_trainers_float_model(method: str, recording: Recording, tmp_path: Path) -> None:
    path = _save(_checkpoint(method, recording), tmp_path)
    model, _ = export(path, tmp_path / "out")
    float_model, _ = load_model(path)
    accel, temp = to_step_units(recording)
    golden_mg = golden_for(model.quantised).run(accel, temp) / ACCEL_PER_MG
    arithmetic = golden_mg - float_model.compensate(integer_recording(recording, accel, temp))
    assert np.sqrt(np.mean(arithmetic**2)) < ARITHMETIC_RMS_MG[method]
    assert np.max(np.abs(arithmetic)) < ARITHMETIC_MAX_MG[method]
    total = golden_mg - float_model.compensate(recording.without_truth())
    noise = np.std(np.diff(recording.accel_mg)) / np.sqrt(2)
    assert np.sqrt(np.mean(total**2)) < noise / 500


def _two_hour_stream(rate: float = 200.0) -> Recording:
    """A 2 h oven-like run: slow temperature cycles and a drift that follows them, plus noise."""
    n = int(2 * 3600 * rate)
    t = np.arange(n) / rate
    rng = np.random.default_rng(5)
    temp = 20.0 + 45.0 * np.sin(2 * np.pi * t / 3000.0) + rng.normal(0, 0.02, n)
    accel = 0.08 * (temp - 20.0) + 1e-3 * (temp - 20.0) ** 2 + rng.normal(0, 0.3, n)
    return Recording({"time_s": t, "temp_c": temp, "accel_mg": accel}, {"sample_rate_hz": str(rate)}, "2h")


@pytest.mark.parametrize(
    ("step_s", "n_steps"), [(1.0, 7_200), pytest.param(0.2, 36_000, marks=pytest.mark.slow)]
)
def test_cell_state_does_not_drift_over_a_two_hour_stream(
    step_s: float, n_steps: int, tmp_path: Path
) -> None:
    """A network with long memory (forget-gate bias + 4: f near 0.98) over 2 h: the golden-versus-
    float error at the end is no larger than at the start (7,200 steps at 1 Hz; 36,000 at 5 Hz slow)."""
    rec = _two_hour_stream()
    fe = tm.frontend_fields(200.0, step_s=step_s)
    checkpoint = tm.dlstm_checkpoint("dlstm-temp", rec, frontend=fe, seed=2, scale=0.3)
    weights = checkpoint["payload"]["weights"]
    weights["b0"][10:20] += 4.0  # long memory: errors would pile up if c were coarse
    weights["b1"][10:20] += 4.0
    path = _save(checkpoint, tmp_path)
    model, _ = export(path, tmp_path / "out")
    float_model, _ = load_model(path)
    accel, temp = to_step_units(rec)
    steps = slice(0, None, fe["decimation"])
    golden_drift = (accel - golden_for(model.quantised).run(accel, temp))[steps] / ACCEL_PER_MG
    float_drift = (rec.accel_mg - float_model.compensate(integer_recording(rec, accel, temp)))[steps]
    err = golden_drift - float_drift
    assert err.size == n_steps
    quarter = err.size // 4
    first, last = np.sqrt(np.mean(err[:quarter] ** 2)), np.sqrt(np.mean(err[-quarter:] ** 2))
    assert last < 1.5 * first + 1e-5
    assert np.max(np.abs(err)) < 1e-2  # mg; this network amplifies perturbations (float too)
    assert np.sqrt(np.mean(err**2)) < 5e-4


def test_cell_state_saturates_explicitly_and_is_flagged(recording: Recording, tmp_path: Path) -> None:
    """Forget gate = 1 in fixed point and i*g = 1: c grows by 1 per step until it saturates at 128."""
    H = 1
    weights = {
        "w_x0": torch.zeros(4 * H, 1),
        "w_h0": torch.zeros(4 * H, H),
        "b0": torch.tensor([20.0, 20.0, 20.0, 0.0]),
        "w_out": torch.ones(1, H),
        "b_out": torch.zeros(1),
    }
    fe = tm.frontend_fields(200.0, run_s=0.005, step_s=0.005)  # one network step per sample
    norm = {"inputs_mean": [0.0], "inputs_std": [1.0], "output_mean": 0.0, "output_std": 1.0}
    checkpoint = tm.checkpoint_dict("dlstm", tm.dlstm_payload("dlstm", weights, fe, norm), (-40.0, 85.0))
    path = _save(checkpoint, tmp_path)
    model, files = export(path, tmp_path / "out", name="sat")
    layer = json.loads(files["sat.manifest.json"])["quantisation"]["layers"][0]
    assert layer["cell_saturation_reachable"] and layer["cell_headroom_bits"] < 0
    accel = np.zeros(400, dtype=np.int64)
    temp = np.full(400, 25_000, dtype=np.int64)
    host = load_module(tmp_path / "out", "sat")
    state, golden = host.new_state(), golden_for(model.quantised)
    np.testing.assert_array_equal(host.run(state, accel, temp), golden.run(accel, temp))
    c_state = host.read_state(state)
    assert c_state["c"][0, 0] == 2**31 - 1 == golden.state()["c"][0, 0]
    assert c_state["flags"] & FLAG_SATURATED and golden.flags & FLAG_SATURATED


@pytest.mark.slow
@pytest.mark.parametrize(
    "method", ["dlstm", "dlstm-ssa", "dlstm-issa", "dlstm-temp", "persistence", "pla", "poly3"]
)
def test_full_paper_recording_verifies_with_zero_mismatches(
    method: str, tmp_path_factory: pytest.TempPathFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    """The issue's acceptance: export + verify on the simulated 2 h validation run (1.44 M samples)."""
    base = tmp_path_factory.getbasetemp() / "paper"
    valid = base / "valid.npz"
    if not valid.exists():
        base.mkdir(exist_ok=True)
        assert trainer_main(["simulate", "--protocol", "paper-oven", "--seed", "2", "-o", str(valid)]) == 0
    rec = read_recording(valid)
    path = _save(_checkpoint(method, rec), base / method)
    out = base / method / "out"
    assert codegen_main(["export", str(path), "-o", str(out)]) == 0
    capsys.readouterr()
    assert codegen_main(["verify", str(path), str(out), str(valid)]) == 0
    printed = capsys.readouterr().out
    assert "samples compared: 1440000" in printed and "mismatches: 0\n" in printed
    assert "final state identical: yes" in printed
    if method in ("pla", "poly3", "persistence"):
        assert "Table 1 (quantised vs float): 7 of 7 figures print identically" in printed
