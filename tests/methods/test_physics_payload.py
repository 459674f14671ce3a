"""A hand-edited physics ``model.pt`` is refused in the same one line by every command that reads
it: an unknown effect, a missing parameter, text where a number or a flag belongs, a reversed clamp
range. Before, evaluate and report failed with a traceback deep in the drift formula, and codegen
wrote C whose tables silently lacked the parameter."""

from __future__ import annotations

from pathlib import Path
from typing import cast

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from tests.testmodels import checkpoint_for, physics_checkpoint, save_checkpoint
from trainer.checkpoint import load_checkpoint, load_model
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import UserError, run_cli
from trainer.greybox.compensator import PhysicsCompensator


def _recording() -> Recording:
    temp = np.concatenate([np.linspace(40.0, -10.0, 300), np.linspace(-10.0, 40.0, 300)])
    accel = 0.0002 * (temp - 15.0) ** 3 + np.random.default_rng(0).normal(0.0, 0.05, temp.size)
    columns = {"time_s": np.arange(temp.size, dtype=float), "temp_c": temp, "accel_mg": accel}
    return Recording(columns, {"sample_rate_hz": "1"}, "payload")


def _edited(rec: Recording, edit: str) -> dict:
    checkpoint = physics_checkpoint(rec)
    payload = checkpoint["payload"]
    effects = payload["effects"]
    if edit == "unknown effect":
        effects[1] = ["quantum_foam", dict(effects[1][1])]
    elif edit == "missing parameter":
        effects[0] = [effects[0][0], {k: v for k, v in effects[0][1].items() if k != "c1_mg_per_c"}]
    elif edit == "parameter as text":
        effects[0][1]["c1_mg_per_c"] = "0.1"
    elif edit == "flag as text":
        payload["with_warmup"] = "yes"
    elif edit == "a width of 0":  # the play operator of width 0 divides by it: NaN everywhere
        effects[3][1]["width_c"] = 0.0
    elif edit == "a lag twice":  # a second proof-mass temperature: the batch formula would ignore it
        effects.append(["thermal_lag", {"tau_s": 300.0}])
    elif edit == "reversed range":
        payload["temp_range_c"] = [40.0, -10.0]
    return checkpoint


EDITS = {
    "unknown effect": "payload.effects[1]: 'quantum_foam' is not a catalogue effect",
    "missing parameter": "payload.effects[0] (bias_poly) has parameters",
    "parameter as text": "payload.effects[0].c1_mg_per_c must be a finite number, got '0.1'",
    "flag as text": "payload.with_warmup must be true or false, got 'yes'",
    "reversed range": "payload.temp_range_c must be increasing, got [40, -10]",
    "a width of 0": "payload.effects[3].width_c must be > 0, got 0.0",
    "a lag twice": "payload.effects: thermal_lag appears 2 times; it changes a temperature the other effects read",
}


@pytest.mark.parametrize("edit", list(EDITS))
def test_an_edited_physics_model_is_one_line_in_every_command(
    edit: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = _recording()
    recording = tmp_path / "rec.csv"
    write_recording(rec, recording)
    intact, model = tmp_path / "intact.pt", tmp_path / "edited.pt"
    save_checkpoint(physics_checkpoint(rec), intact)
    save_checkpoint(_edited(rec, edit), model)
    assert (
        run_cli(trainer_main, ["evaluate", str(intact), str(recording), "--out-dir", str(tmp_path / "ok")])
        == 0
    )
    capsys.readouterr()
    commands = {
        "evaluate": (
            trainer_main,
            ["evaluate", str(model), str(recording), "--out-dir", str(tmp_path / "ev")],
        ),
        "report": (
            trainer_main,
            ["report", str(model), "--recording", str(recording), "-o", str(tmp_path / "rp")],
        ),
        "export": (codegen_main, ["export", str(model), "-o", str(tmp_path / "c")]),
    }
    lines = set()
    for main, argv in commands.values():
        assert run_cli(main, argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "Traceback" not in err and EDITS[edit] in err and str(model) in err
        lines.add(err)
    assert len(lines) == 1  # the same refusal everywhere
    assert not any((tmp_path / name).exists() for name in ("ev", "rp", "c"))


def test_a_forced_undetermined_term_saves_a_model_every_command_reads(real_run: Path, tmp_path: Path) -> None:
    """`--effects hysteresis_offset,thermal_lag` on the real run's accel z: the lag's time constant is
    not determined (its standard deviation is infinite). The fit used to write that inf into the model,
    which every other command then refused as "damaged or hand-edited"; now the model exports and
    evaluates, the lag still flagged as undetermined."""
    imu = tmp_path / "imu.csv"
    assert (
        run_cli(
            trainer_main,
            ["import", str(real_run), "--preset", "tofupilot", "--channels", "all", "-o", str(imu)],
        )
        == 0
    )
    models = tmp_path / "models"
    argv = ["fit", "--method", "physics", str(imu), "--channels", "accel0_z", "-o", str(models)]
    assert run_cli(trainer_main, [*argv, "--effects", "hysteresis_offset,thermal_lag"]) == 0
    model = models / "accel0_z.pt"
    report = load_checkpoint(model)["payload"]["report"]
    assert "thermal_lag.tau_s" in report["at_bound"]
    assert "tau_s" not in report["std"]["thermal_lag"]
    assert all(np.isfinite(v) for stds in report["std"].values() for v in stds.values())
    assert run_cli(codegen_main, ["export", str(model), "-o", str(tmp_path / "c"), "--name", "t_hl"]) == 0
    assert (
        run_cli(
            trainer_main,
            ["evaluate", str(models), str(imu), "--channels", "accel0_z", "--out-dir", str(tmp_path / "ev")],
        )
        == 0
    )


@pytest.mark.parametrize("method", ["poly3", "physics"])
def test_a_valid_range_beyond_the_clamp_range_is_refused(
    method: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`valid_temp_range_c` edited to -40 .. 120 degC on a model that clamps its temperature to its
    fitted range: the module would have declared 120 degC valid and never flagged the extrapolation
    between the fitted end and 120. Refused in one line by export and evaluate; nothing written."""
    rec = _recording()
    checkpoint = checkpoint_for(method, rec)
    save_checkpoint({**checkpoint, "valid_temp_range_c": [-40.0, 120.0]}, tmp_path / "m.pt")
    write_recording(rec, tmp_path / "r.csv")
    model, never = str(tmp_path / "m.pt"), str(tmp_path / "never")
    for main, argv in (
        (codegen_main, ["export", model, "-o", never]),
        (trainer_main, ["evaluate", model, str(tmp_path / "r.csv"), "--out-dir", never]),
    ):
        assert run_cli(main, argv) == 2
        err = capsys.readouterr().err.strip()
        assert (
            "\n" not in err
            and "'valid_temp_range_c' -40 .. 120 degC reaches beyond 'payload.temp_range_c'" in err
        )
    assert not (tmp_path / "never").exists()


def test_a_gyroscope_model_file_names_its_parameters_in_deg_per_s(tmp_path: Path) -> None:
    """physics-catalogue.md, "Other channels": on a deg/s channel an amplitude parameter carries
    ``dps`` in place of ``mg``; another program reading ``model.pt`` parses it against those names.
    A file written before (catalogue names on a gyroscope) still loads, to the same model."""
    rec = _recording()
    checkpoint = physics_checkpoint(rec)
    mg_effects = [[name, dict(params)] for name, params in checkpoint["payload"]["effects"]]
    save_checkpoint(checkpoint, tmp_path / "mg.pt")
    model = cast(PhysicsCompensator, load_model(tmp_path / "mg.pt")[0])
    model.report = {"unit": "dps"}  # what the fit records for a gyroscope channel
    checkpoint["payload"] = model.to_payload()
    names = [k for _, params in checkpoint["payload"]["effects"] for k in params]
    amplitudes = [k for _, params in mg_effects for k in params if "mg" in k.split("_")]
    assert amplitudes and not [k for k in names if "mg" in k.split("_")]
    assert sorted(names) == sorted(k.replace("_mg", "_dps") for _, params in mg_effects for k in params)
    save_checkpoint(checkpoint, tmp_path / "dps.pt")
    dps_model, _ = load_model(tmp_path / "dps.pt")
    old = dict(checkpoint, payload=dict(checkpoint["payload"], effects=mg_effects))
    save_checkpoint(old, tmp_path / "old.pt")
    old_model, _ = load_model(tmp_path / "old.pt")
    drift = model.predict_drift(rec)
    assert np.abs(drift).max() > 0.1
    np.testing.assert_array_equal(dps_model.predict_drift(rec), drift)
    np.testing.assert_array_equal(old_model.predict_drift(rec), drift)
    mixed = [list(e) for e in checkpoint["payload"]["effects"]]
    mixed[0] = [mixed[0][0], {**mg_effects[0][1], "c1_dps_per_c": 0.1}]
    mixed[0][1].pop("c1_mg_per_c")
    save_checkpoint(
        dict(checkpoint, payload=dict(checkpoint["payload"], effects=mixed)), tmp_path / "mixed.pt"
    )
    with pytest.raises(UserError, match=r"payload.effects\[0\] \(bias_poly\) has parameters .*c0_dps"):
        load_model(tmp_path / "mixed.pt")
