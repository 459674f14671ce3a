"""The golden model against the trainer's float models: the error budget (golden minus float at
most 1e-3 mg RMS and 5e-3 mg maximum, Allan improvements within 0.1 percentage point, drift left
within 1 % of the float model's), the cell state's precision over a 2 h stream, the documented
saturation of the cell state, and (slow) the full verify."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from codegen.cli import main as codegen_main
from codegen.export import export
from codegen.families.stream.golden import GoldenStream
from codegen.golden_select import golden_for
from codegen.hostbuild import load_module
from codegen.qformats import H_FRAC
from codegen.quantize import ACCEL_PER_MG, FLAG_SATURATED
from codegen.verify import (
    Table1Check,
    error_budget,
    held_fine_output,
    integer_recording,
    to_step_units,
    verify,
)
from tests import testmodels as tm
from trainer.checkpoint import load_model
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording

LSB_MG = 1.0 / ACCEL_PER_MG  # the output's unit, 1/16 ug
# The budget of the generated arithmetic (golden minus float on the same integer inputs), mg: the
# issue's restatement for the networks (16-bit operands, table activations); the memoryless methods
# and persistence keep the output's rounding to 1/16 ug as their only error (uniform, 0.29 LSB RMS;
# persistence: error feedback, 0.41 LSB RMS, at most one LSB).
BUDGET_RMS_MG, BUDGET_MAX_MG = 1e-3, 5e-3
ARITHMETIC_RMS_MG = {"dlstm": BUDGET_RMS_MG, "dlstm-temp": BUDGET_RMS_MG, "persistence": 0.45 * LSB_MG}
ARITHMETIC_RMS_MG |= {"pla": 0.32 * LSB_MG, "poly3": 0.32 * LSB_MG}
ARITHMETIC_MAX_MG = {"dlstm": BUDGET_MAX_MG, "dlstm-temp": BUDGET_MAX_MG, "persistence": 1.0 * LSB_MG + 1e-6}
ARITHMETIC_MAX_MG |= {"pla": 0.5 * LSB_MG + 1e-6, "poly3": 0.5 * LSB_MG + 1e-6}
IMPROVEMENT_PP = 0.1  # Allan improvements of the quantised model within 0.1 percentage point
DRIFT_LEFT_RATIO = 0.01  # drift left within 1 % of the float model's


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
    golden = golden_for(model.quantised)
    fine = None
    if isinstance(golden, GoldenStream):
        golden.fine_estimates = []
    out = golden.run(accel, temp)
    if isinstance(golden, GoldenStream):
        assert golden.fine_estimates is not None
        fine = held_fine_output(accel, golden.fine_estimates, golden.model.frontend.decimation)
    budget = error_budget(
        out,
        float_model.compensate(recording.without_truth()),
        float_model.compensate(integer_recording(recording, accel, temp)),
        recording.accel_mg,
        recording.sample_rate_hz,
        fine,
    )
    assert budget.arithmetic_rms_mg < ARITHMETIC_RMS_MG[method]
    assert budget.arithmetic_max_abs_mg < ARITHMETIC_MAX_MG[method]
    if fine is not None and method != "persistence":
        assert budget.network_rms_mg is not None and budget.network_max_abs_mg is not None
        assert budget.network_rms_mg < BUDGET_RMS_MG and budget.network_max_abs_mg < BUDGET_MAX_MG
    assert budget.rms_mg < budget.noise_mg / 300  # 300 times below the sensor's white noise


# ------------------------------------------------------------------------- trained networks, Table 1

FAST_FIT = ("--population", "2", "--iterations", "150", "--quiet")


def _simulate_pair(directory: Path, duration_s: int | None) -> tuple[Path, Path]:
    """The paper's oven protocol: training run seed 1, validation run seed 2."""
    directory.mkdir(parents=True, exist_ok=True)
    paths = directory / "train.npz", directory / "valid.npz"
    extra = ["--duration", str(duration_s)] if duration_s else []
    for seed, path in zip((1, 2), paths, strict=True):
        if not path.exists():
            args = ["simulate", "--protocol", "paper-oven", "--seed", str(seed), *extra, "-o", str(path)]
            assert trainer_main(args) == 0
    return paths


def _on_the_mdegc_grid(path: Path, directory: Path) -> Path:
    """The recording with its temperatures rounded to whole mdegC, as a digital sensor delivers them."""
    rec = read_recording(path)
    grid = directory / "valid_mdegc.npz"
    write_recording(
        Recording({**rec.columns, "temp_c": np.rint(rec.temp_c * 1000) / 1000}, rec.meta, "grid"), grid
    )
    return grid


def _assert_within_budget(table: Table1Check | None) -> None:
    assert table is not None
    assert table.max_improvement_diff_pp < IMPROVEMENT_PP, table.text
    ratio = table.drift_left_ratio
    assert ratio is not None and ratio < DRIFT_LEFT_RATIO, table.drift_left_mg
    assert table.within_budget


def _check_trained(method: str, train: Path, valid: Path, work: Path, cycles: int) -> None:
    model = work / f"{method}.pt"
    assert (
        trainer_main(
            ["fit", "--method", method, str(train), "-o", str(model), *FAST_FIT, "--cycles", str(cycles)]
        )
        == 0
    )
    export(model, work / "out")
    result = verify(model, work / "out", valid)
    assert result.mismatches == 0 and result.state_equal
    b = result.budget
    assert b.network_rms_mg is not None and b.network_max_abs_mg is not None
    assert b.network_rms_mg < BUDGET_RMS_MG and b.network_max_abs_mg < BUDGET_MAX_MG
    assert b.arithmetic_rms_mg < BUDGET_RMS_MG and b.arithmetic_max_abs_mg < BUDGET_MAX_MG
    _assert_within_budget(result.table1_integer_inputs)
    if method == "dlstm-temp":
        # the rate input differentiates 5 s temperature means: the API's 1 mdegC rounding of the
        # simulation's float temperatures moves the float model's own figures, so the comparison
        # with the float model is made on temperatures a digital sensor could give
        result = verify(model, work / "out", _on_the_mdegc_grid(valid, work))
    b = result.budget
    assert b.rms_mg < BUDGET_RMS_MG and b.max_abs_mg < BUDGET_MAX_MG
    _assert_within_budget(result.table1)
    print(f"{method}: {b.rms_mg:.3g} mg RMS, {b.max_abs_mg:.3g} mg max; {result.table1}")


@pytest.mark.parametrize(("method", "cycles"), [("dlstm-issa", 2), ("dlstm-temp", 0)])
def test_trained_networks_print_the_float_models_table1(
    method: str, cycles: int, tmp_path_factory: pytest.TempPathFactory, tmp_path: Path
) -> None:
    """The error budget on small but real DLSTMs (30 min training and validation runs)."""
    train, valid = _simulate_pair(tmp_path_factory.getbasetemp() / "paper_short", 1800)
    _check_trained(method, train, valid, tmp_path, cycles)


@pytest.mark.slow
@pytest.mark.parametrize(("method", "cycles"), [("dlstm-issa", 3), ("dlstm", 0), ("dlstm-temp", 0)])
def test_trained_networks_print_the_float_models_table1_on_the_full_run(
    method: str, cycles: int, tmp_path_factory: pytest.TempPathFactory, tmp_path: Path
) -> None:
    """The same on the paper's full 2 h runs (1.44 M samples each)."""
    train, valid = _simulate_pair(tmp_path_factory.getbasetemp() / "paper_full", None)
    _check_trained(method, train, valid, tmp_path, cycles)


def _two_hour_stream(rate: float = 200.0) -> Recording:
    """A 2 h oven-like run: slow temperature cycles and a drift that follows them, plus noise."""
    n = int(2 * 3600 * rate)
    t = np.arange(n) / rate
    rng = np.random.default_rng(5)
    temp = 20.0 + 45.0 * np.sin(2 * np.pi * t / 3000.0) + rng.normal(0, 0.02, n)
    accel = 0.08 * (temp - 20.0) + 1e-3 * (temp - 20.0) ** 2 + rng.normal(0, 0.3, n)
    return Recording({"time_s": t, "temp_c": temp, "accel_mg": accel}, {"sample_rate_hz": str(rate)}, "2h")


def _on_the_golden_weight_grid(checkpoint: dict[str, Any], model: Any) -> dict[str, Any]:
    """``checkpoint`` with the layers' weights and biases replaced by the quantised model's int16
    weights and int32 biases read back as reals (layer 0's input columns each at Q(A - its input's
    fraction), h and the later layers' inputs at Q(A - 15)); the head stays float."""
    out = copy.deepcopy(checkpoint)
    weights = out["payload"]["weights"]
    input_fracs = np.array([q.frac for q in model.quantised.inputs])
    for index, layer in enumerate(model.quantised.layers):
        x_fracs = layer.acc_frac - (input_fracs if index == 0 else H_FRAC)
        real = {
            f"w_x{index}": layer.wx.q / 2.0 ** np.broadcast_to(x_fracs, layer.wx.q.shape),
            f"w_h{index}": layer.wh.q / 2.0 ** (layer.acc_frac - H_FRAC),
            f"b{index}": layer.b / 2.0**layer.acc_frac,
        }
        for name, value in real.items():
            weights[name] = torch.tensor(value, dtype=weights[name].dtype)
    return out


@pytest.mark.parametrize(
    ("step_s", "n_steps"), [(1.0, 7_200), pytest.param(0.2, 36_000, marks=pytest.mark.slow)]
)
def test_cell_state_does_not_drift_over_a_two_hour_stream(
    step_s: float, n_steps: int, tmp_path: Path
) -> None:
    """A network with long memory (forget-gate bias + 4: f near 0.98) over 2 h: the golden-versus-
    float error at the end is no larger than at the start (7,200 steps at 1 Hz; 36,000 at 5 Hz slow).

    The + 4 biases cost the layers one accumulator bit (Q28: W_h at Q13, docs/codegen.md "Weight
    formats"), and this network switches between two states at the extremes of the temperature rate,
    where it amplifies any perturbation: at 5 Hz the weight grid alone moves the float model by up to
    1e-2 mg there. So the budget is asserted on the arithmetic, against the float model run with the
    golden's own weights (an independent model of the weight grid); the whole error, weight grid
    included, is held to the budget at 1 Hz.
    """
    rec = _two_hour_stream()
    fe = tm.frontend_fields(200.0, step_s=step_s)
    checkpoint = tm.dlstm_checkpoint("dlstm-temp", rec, frontend=fe, seed=2, scale=0.3)
    weights = checkpoint["payload"]["weights"]
    weights["b0"][10:20] += 4.0  # long memory: errors would pile up if c were coarse
    weights["b1"][10:20] += 4.0
    path = _save(checkpoint, tmp_path)
    model, _ = export(path, tmp_path / "out")
    float_model, _ = load_model(path)
    grid_model, _ = load_model(_save(_on_the_golden_weight_grid(checkpoint, model), tmp_path / "grid"))
    accel, temp = to_step_units(rec)
    golden = golden_for(model.quantised)
    assert isinstance(golden, GoldenStream)
    golden.fine_estimates = []  # the network's estimates before the output's rounding
    golden.run(accel, temp)
    golden_drift = np.asarray(golden.fine_estimates) / ACCEL_PER_MG
    ints = integer_recording(rec, accel, temp)
    float_drift = (ints.accel_mg - float_model.compensate(ints))[:: fe["decimation"]]
    grid_drift = (ints.accel_mg - grid_model.compensate(ints))[:: fe["decimation"]]
    err, arithmetic = golden_drift - float_drift, golden_drift - grid_drift
    assert err.size == n_steps
    quarter = err.size // 4
    first, last = np.sqrt(np.mean(err[:quarter] ** 2)), np.sqrt(np.mean(err[-quarter:] ** 2))
    assert last < 1.5 * first + 1e-6
    assert np.max(np.abs(arithmetic)) < BUDGET_MAX_MG and np.sqrt(np.mean(arithmetic**2)) < BUDGET_RMS_MG
    if step_s >= 1.0:
        assert np.max(np.abs(err)) < BUDGET_MAX_MG and np.sqrt(np.mean(err**2)) < BUDGET_RMS_MG
    print(
        f"golden - float: RMS {np.sqrt(np.mean(err**2)):.3g} first {first:.3g} last {last:.3g} "
        f"max {np.max(np.abs(err)):.3g}; golden - float on its weight grid: RMS "
        f"{np.sqrt(np.mean(arithmetic**2)):.3g} max {np.max(np.abs(arithmetic)):.3g} mg"
    )


def test_cell_state_saturates_explicitly_and_is_flagged(recording: Recording, tmp_path: Path) -> None:
    """Forget gate = 1 - 2**-16 and i*g = 1: c grows by about 1 per step until it saturates at 128."""
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
    ("method", "schedule"),
    [
        *(
            (m, "step")
            for m in ("dlstm", "dlstm-ssa", "dlstm-issa", "dlstm-temp", "persistence", "pla", "poly3")
        ),
        ("dlstm-issa", "spread"),
        ("dlstm-temp", "spread"),
    ],
)
def test_full_paper_recording_verifies_with_zero_mismatches(
    method: str, schedule: str, tmp_path_factory: pytest.TempPathFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    """The issue's acceptance: export + verify on the simulated 2 h validation run (1.44 M samples)."""
    _, valid = _simulate_pair(tmp_path_factory.getbasetemp() / "paper_full", None)
    rec = read_recording(valid)
    base = tmp_path_factory.getbasetemp() / "random"
    path = _save(_checkpoint(method, rec), base / method)
    out = base / method / f"out_{schedule}"
    extra = [] if schedule == "step" else ["--schedule", schedule]
    assert codegen_main(["export", str(path), "-o", str(out), *extra]) == 0
    capsys.readouterr()
    assert codegen_main(["verify", str(path), str(out), str(valid)]) == 0
    printed = capsys.readouterr().out
    assert "samples compared: 1440000" in printed and "mismatches: 0\n" in printed
    assert "final state identical: yes" in printed
    if schedule != "step":
        assert "drift removed = the step schedule's delayed by 199 samples on every sample: yes" in printed
