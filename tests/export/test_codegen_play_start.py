"""The branch at power-on (``play_start_c``) and auto's ``physics-branch-room`` candidate.

A cycle 60 -> -10 -> 60 -> -10 degC at 1 Hz whose accel0_x carries a cubic and a branch offset
(amp 1.5 mg, 30 degC wide) with the play operator started from 25 degC: at the first sample (60
degC, more than half the width above 25) the sensor is on the heating branch, where the catalogue's
half-way start puts it mid-way. The least-squares fit must find the loop and the start; the float
stream, the golden model, the one-channel C and the IMU C must all start there.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from codegen.export import export
from codegen.families.physics.quantise import QPhysics
from codegen.golden_select import golden_for
from codegen.hostbuild import (
    CMD_INIT,
    CMD_RESET,
    SANITIZER_FLAGS,
    build_harness,
    load_module,
    run_harness,
    write_vectors,
)
from codegen.imu import load_imu
from codegen.imu_verify import host_run, step_inputs, verify_imu
from codegen.quantize import ACCEL_PER_MG
from codegen.render import render_template
from codegen.verify import to_step_units
from tests import testmodels as tm
from tests.export.test_imu_physics import RATE_HZ, SEGMENTS  # the same 1 Hz cycle from 60 degC
from tests.golden_checks import replay
from trainer.checkpoint import load_checkpoint, load_model, save_model
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import run_cli
from trainer.fitting import fit_with_stats
from trainer.greybox.compensator import PhysicsCompensator
from trainer.greybox.stream import PhysicsStream
from trainer.physics.effects import EffectConfig, drift

FROM_C = 25.0
NOISE_MG = 0.05
TRUTH = (
    EffectConfig(
        "bias_poly", {"c0_mg": 0.4, "c1_mg_per_c": 0.15, "c2_mg_per_c2": 1e-3, "c3_mg_per_c3": -5e-6}
    ),
    EffectConfig("hysteresis_offset", {"amp_mg": 1.5, "width_c": 30.0}),
)
ROOM = {"effects": "hysteresis_offset", "play_start_c": FROM_C, "least_squares": True}
NAME = "tdc_room"


def recording(seed: int = 7) -> Recording:
    rng = np.random.default_rng(seed)
    temp = np.concatenate([np.linspace(a, b, int(d * RATE_HZ), endpoint=False) for d, a, b in SEGMENTS])
    time_s = np.arange(temp.size) / RATE_HZ
    u = (temp - 25.0) / 35.0
    columns = {
        "time_s": time_s,
        "temp_c": temp,
        "accel0_x_mg": drift(TRUTH, time_s, temp, play_start_c=FROM_C).total
        + rng.normal(0, NOISE_MG, temp.size),
        "accel0_y_mg": -3.0 + 2.0 * u - 1.5 * u**2 + rng.normal(0, NOISE_MG, temp.size),
    }
    columns["accel_mg"] = columns["accel0_x_mg"]
    return Recording(columns, {"sample_rate_hz": f"{RATE_HZ:g}", "channel": "accel0_x"}, "room-start")


@pytest.fixture(scope="module")
def fitted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("room")
    rec = recording()
    write_recording(rec, root / "rec.npz")
    model, stats = fit_with_stats("physics", rec, ROOM)
    save_model(model, root / "room.pt", train_stats=stats, valid_temp_range_c=stats.temp_range_c)
    assert (
        trainer_main(
            [
                "fit",
                "--method",
                "poly3",
                "--channels",
                "accel0_y",
                str(root / "rec.npz"),
                "-o",
                str(root / "y"),
            ]
        )
        == 0
    )
    assert codegen_main(["export", str(root / "room.pt"), "-o", str(root / "one"), "--name", NAME]) == 0
    return {"root": root, "rec": root / "rec.npz", "model": root / "room.pt", "y": root / "y" / "accel0_y.pt"}


def _params(path: Path) -> dict[str, dict[str, float]]:
    model, _ = load_model(path)
    assert isinstance(model, PhysicsCompensator)
    return {e.identifier: dict(e.params) for e in model.effects}


def test_the_least_squares_fit_finds_the_loop_and_the_half_way_start_does_not(
    fitted: dict[str, Path],
) -> None:
    branch = _params(fitted["model"])["hysteresis_offset"]
    assert abs(branch["width_c"] - 30.0) <= 1.0 and abs(branch["amp_mg"] - 1.5) < 0.05 * 1.5
    rec = recording()
    room, _ = load_model(fitted["model"])
    halfway = PhysicsCompensator(effects="hysteresis_offset", least_squares=True).fit(rec)
    rms = {
        name: float(np.std(rec.accel_mg - m.predict_drift(rec)))  # the offset policy moved the constant
        for name, m in (("room", room), ("half-way", halfway))
    }
    assert rms["room"] < 1.1 * NOISE_MG < 2 * NOISE_MG < rms["half-way"], rms  # the start is in the data


def test_the_stream_starts_where_the_batch_formula_does(fitted: dict[str, Path]) -> None:
    model, _ = load_model(fitted["model"])
    assert isinstance(model, PhysicsCompensator) and model.play_start_c == FROM_C
    rec = recording()
    stream = PhysicsStream(model.model, 1.0 / RATE_HZ)
    streamed = np.array([stream.step(t) for t in rec.temp_c.tolist()])
    np.testing.assert_allclose(streamed, model.predict_drift(rec), rtol=0, atol=1e-9)


def test_the_c_starts_on_the_branch_the_journey_from_room_temperature_left(
    fitted: dict[str, Path], tmp_path: Path
) -> None:
    """At 60 degC, 35 degC above the start and more than w/2 = 15 degC, the play operator is clamped to
    T - w/2: the branch term is +amp where the half-way start gives 0. Independent of the golden model:
    the first output of the C minus that of the same checkpoint without a start is -amp."""
    raw = load_checkpoint(fitted["model"])
    halfway = {**raw, "payload": {**raw["payload"], "play_start_c": None}}
    tm.save_checkpoint(halfway, tmp_path / "halfway.pt")
    assert (
        codegen_main(["export", str(tmp_path / "halfway.pt"), "-o", str(tmp_path / "h"), "--name", NAME]) == 0
    )
    temp = np.full(5, 60_000, dtype=np.int32)
    accel = np.zeros(5, dtype=np.int32)
    outputs = {}
    for label, folder in (("room", fitted["root"] / "one"), ("half-way", tmp_path / "h")):
        module = load_module(folder, NAME)
        outputs[label] = module.run(module.new_state(), accel, temp) / ACCEL_PER_MG
    amp = _params(fitted["model"])["hysteresis_offset"]["amp_mg"]
    np.testing.assert_allclose(outputs["room"] - outputs["half-way"], -amp, atol=2e-3)
    assert load_checkpoint(tmp_path / "halfway.pt")["payload"]["play_start_c"] is None


def test_c_equals_golden_under_sanitizers_and_starts_again_after_reset_and_init(
    fitted: dict[str, Path], tmp_path: Path
) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    loaded, _ = export(fitted["model"], tmp_path / "out", name=NAME)
    assert isinstance(loaded.quantised, QPhysics) and loaded.quantised.play_start_q is not None
    accel, temp = (v.astype(np.int64) for v in to_step_units(recording()))
    commands = np.zeros(accel.size, dtype=np.int64)
    commands[2_500], commands[5_000] = CMD_RESET, CMD_INIT
    write_vectors(tmp_path / "v.bin", accel, temp, commands)
    harness = render_template("harness_vectors.c.j2", loaded.quantised, NAME, loaded.sha256)
    binary = build_harness(tmp_path / "out", NAME, harness, tmp_path / "san", flags=("-O1", *SANITIZER_FLAGS))
    run_harness(binary, tmp_path / "v.bin", tmp_path / "o.bin")
    c_out = np.frombuffer((tmp_path / "o.bin").read_bytes(), dtype="<i4").astype(np.int64)
    np.testing.assert_array_equal(c_out, replay(golden_for(loaded.quantised), accel, temp, commands))


def test_the_imu_module_starts_each_physics_channel_as_its_own_module_does(
    fitted: dict[str, Path], tmp_path: Path
) -> None:
    models = [fitted["model"], fitted["y"]]
    assert codegen_main(["export", *map(str, models), "-o", str(tmp_path / "imu"), "--name", "imu0"]) == 0
    from trainer.data.recording_io import read_recording

    rec = read_recording(fitted["rec"])
    if shutil.which("gcc") is not None:
        result = verify_imu(models, tmp_path / "imu", rec)
        assert result.runs[0].mismatches == [0, 0] and result.runs[0].state_equal
    one = load_module(fitted["root"] / "one", NAME)
    imu = load_imu(models)
    raw, temp = step_inputs(imu, rec)
    single = one.run(one.new_state(), raw[:, 0].astype(np.int32), temp[:, 0].astype(np.int32))
    out, _, _ = host_run(tmp_path / "imu", "imu0", raw, temp, None, None)
    np.testing.assert_array_equal(out[:, 0], single)


def test_auto_ships_the_room_start_on_the_bundled_gyro_x_and_it_beats_the_cubic_on_every_segment(
    real_run: Path,
) -> None:
    """Issue 20's gyro x: each cooling and the heating held out in turn, warm and cold."""
    from trainer.data.channels import channel_view, select_channels
    from trainer.data.importer import import_foreign, options_with_preset
    from trainer.scoring.crossval import UNCOMPENSATED
    from trainer.selection import select

    rec = import_foreign(real_run, options_with_preset("tofupilot", channels=("all",)))
    gyro = channel_view(rec, select_channels(rec, ("gyro0_x",))[0])
    selection = select(gyro, labels=("none", "poly3", "physics-branch-room"))
    assert selection.chosen == "physics-branch-room"
    room, cubic, none = (selection.cv.results[k] for k in ("physics-branch-room", "poly3", UNCOMPENSATED))
    for i, fold in enumerate(room.folds):
        assert max(fold.warm_rms, fold.cold_rms) < cubic.folds[i].warm_rms, i
        assert abs(fold.cold_rms - fold.warm_rms) < 0.01 * fold.warm_rms, i  # a cold start agrees with warm
        assert fold.warm_rms < 1.05 * min(cubic.folds[i].warm_rms, none.folds[i].warm_rms), i
    assert np.median([f.warm_rms for f in room.folds]) < 0.6 * np.median([f.warm_rms for f in cubic.folds])


def test_a_flight_stack_export_refuses_it_by_the_name_auto_chose(
    fitted: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [
        "fit",
        "--method",
        "auto",
        "--candidates",
        "none,poly3,physics-branch-room",
        "--channels",
        "accel0_x",
    ]
    assert trainer_main([*argv, str(fitted["rec"]), "-o", str(tmp_path / "auto")]) == 0
    model = tmp_path / "auto" / "accel0_x.pt"
    assert load_checkpoint(model)["train_stats"]["selection"]["chosen"] == "physics-branch-room"
    capsys.readouterr()
    assert (
        run_cli(codegen_main, ["export", str(model), "--format", "px4-params", "-o", str(tmp_path / "px4")])
        != 0
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "method 'physics-branch-room' is not a cubic of the temperature" in err[0], err
    assert not (tmp_path / "px4").exists()


def test_a_half_way_start_header_gives_the_branch_terms_power_on_error_in_numbers(tmp_path: Path) -> None:
    """Started mid-way, the branch term is off by up to its amplitude until T has moved by w/2: the
    header and manifest say how much and how far, from the model's own parameters."""
    rec = recording()
    model, stats = fit_with_stats("physics", rec, {"effects": "hysteresis_offset", "least_squares": True})
    save_model(model, tmp_path / "half.pt", train_stats=stats, valid_temp_range_c=stats.temp_range_c)
    assert (
        codegen_main(["export", str(tmp_path / "half.pt"), "-o", str(tmp_path / "c"), "--name", "half"]) == 0
    )
    branch = _params(tmp_path / "half.pt")["hysteresis_offset"]
    said = f"|its amplitude|, {abs(branch['amp_mg']):.3g} mg, until T has moved by w/2 = {branch['width_c'] / 2:.3g} degC"
    header = " ".join((tmp_path / "c" / "half.h").read_text().replace(" * ", " ").split())
    assert said in header and said in (tmp_path / "c" / "half.manifest.json").read_text()


def test_a_room_start_header_bounds_the_error_of_a_sensor_that_came_another_way(tmp_path: Path) -> None:
    """Started from 25 degC, a sensor that came another way (a reboot after an excursion, a reset
    mid-run) can be on the other branch: off by up to twice the amplitude until T has moved by the
    width. The header says how much and how far, from the model's own parameters."""
    rec = recording()
    model, stats = fit_with_stats("physics", rec, ROOM)
    save_model(model, tmp_path / "room.pt", train_stats=stats, valid_temp_range_c=stats.temp_range_c)
    assert (
        codegen_main(["export", str(tmp_path / "room.pt"), "-o", str(tmp_path / "c"), "--name", "room"]) == 0
    )
    branch = _params(tmp_path / "room.pt")["hysteresis_offset"]
    header = " ".join((tmp_path / "c" / "room.h").read_text().replace(" * ", " ").split())
    said = (
        f"in all at most {2 * abs(branch['amp_mg']):.3g} mg until T has moved by {branch['width_c']:.3g} degC"
    )
    assert said in header, header
    assert f"width {branch['width_c']:.3g} degC" in header
