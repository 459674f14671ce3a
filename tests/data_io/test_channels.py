"""Several channels in one recording: --channels for fit/evaluate/import, the IMU C module and its blob.

A small synthetic IMU recording (accelerometer and gyroscope x/y/z sharing a temperature, and a
barometer with its own) is written by the test; every per-channel result is compared with the
one-channel path run on that column alone, and the IMU module with each channel's golden model.
"""

from __future__ import annotations

import json
import shutil
import struct
import subprocess
import zlib
from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from codegen.imu import BLOB_HEADER, CHANNEL_HEADER, encode_blob, imu_golden, load_imu
from codegen.imu_verify import load_host_module, step_inputs, verify_imu
from trainer.checkpoint import load_checkpoint, load_model
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording
from trainer.errors import UserError, run_cli

RATE_HZ = 2.0
N = 1200  # 10 minutes at 2 Hz: one heating and one cooling ramp
CHANNELS = ("accel0_x", "accel0_y", "accel0_z", "gyro0_x", "gyro0_y", "gyro0_z")


def _ramp(n: int, lo: float, hi: float) -> np.ndarray:
    half = n // 2
    return np.concatenate([np.linspace(lo, hi, half), np.linspace(hi, lo, n - half)])


def imu_recording(n: int = N, seed: int = 3, temp_span: tuple[float, float] = (-10.0, 60.0)) -> Recording:
    """Six IMU channels (own cubic drift each), a barometer with its own temperature; no truth columns."""
    rng = np.random.default_rng(seed)
    temp = _ramp(n, *temp_span) + rng.normal(0, 0.01, n)
    baro_temp = temp + 2.0
    columns: dict[str, np.ndarray] = {"time_s": np.arange(n) / RATE_HZ, "temp_c": temp}
    for k, name in enumerate(CHANNELS):
        u = (temp - 25.0) / 35.0
        coefficients = rng.normal(0, [2.0, 5.0, 1.5, 0.8]) * (0.05 if name.startswith("gyro") else 1.0)
        level = -1000.0 if name == "accel0_z" else 10.0 * k
        drift = sum(c * u**j for j, c in enumerate(coefficients))
        noise = rng.normal(0, 0.002 if name.startswith("gyro") else 0.05, n)
        columns[f"{name}_{'dps' if name.startswith('gyro') else 'mg'}"] = level + drift + noise
    columns["baro0_pa"] = (
        101325.0 + 3.0 * (baro_temp - 25.0) + 0.02 * (baro_temp - 25.0) ** 2 + rng.normal(0, 0.5, n)
    )
    columns["baro0_temp_c"] = baro_temp
    columns["accel_mg"] = columns["accel0_z_mg"]
    return Recording(columns, {"sample_rate_hz": f"{RATE_HZ:g}", "channel": "accel0_z"}, "synthetic-imu")


def one_axis(rec: Recording, channel: str, temp_column: str = "temp_c") -> Recording:
    """The channel as an ordinary one-axis recording (what a user would write by hand)."""
    unit = "pa" if channel.startswith("baro") else ("dps" if channel.startswith("gyro") else "mg")
    column = f"{channel}_{unit}"
    return Recording(
        {"time_s": rec.time_s, "temp_c": rec.columns[temp_column], "accel_mg": rec.columns[column]},
        # a one-channel view's metadata: the writer keeps deg/s and Pa in the channel's own column
        # (accel_mg is milli-g only), which the metadata point to
        {
            "sample_rate_hz": rec.meta["sample_rate_hz"],
            **({"unit": unit, "channel": channel} if unit != "mg" else {}),
        },
        f"{channel}.npz",
    )


@pytest.fixture(scope="module")
def imu(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("imu")
    rec = imu_recording()
    write_recording(rec, root / "imu.csv")
    write_recording(imu_recording(seed=4, temp_span=(-30.0, 90.0)), root / "wide.npz")  # beyond the range
    assert (
        trainer_main(
            [
                "fit",
                "--method",
                "poly3",
                str(root / "imu.csv"),
                "--channels",
                "all",
                "-o",
                str(root / "poly3"),
            ]
        )
        == 0
    )
    assert (
        trainer_main(
            ["fit", "--method", "pla", "--intervals", "4", str(root / "imu.csv"), "--channels", "gyro0_x,gyro0_y,baro0",
             "-o", str(root / "pla")]
        )
        == 0
    )  # fmt: skip
    return {"root": root, "rec": root / "imu.csv", "wide": root / "wide.npz"}


def test_fit_per_channel_equals_a_one_channel_fit_of_that_column(
    imu: dict[str, Path], tmp_path: Path
) -> None:
    rec = read_recording(imu["rec"])
    index = json.loads((imu["root"] / "poly3" / "channels.json").read_text())
    assert [c["channel"] for c in index["channels"]] == [*CHANNELS, "baro0"]
    units = {c["channel"]: c["unit"] for c in index["channels"]}
    assert units["accel0_x"] == "mg" and units["gyro0_z"] == "deg/s" and units["baro0"] == "Pa"
    for channel in (*CHANNELS, "baro0"):
        temp_column = "baro0_temp_c" if channel == "baro0" else "temp_c"
        single = tmp_path / f"{channel}.npz"
        write_recording(one_axis(rec, channel, temp_column), single)
        assert (
            trainer_main(["fit", "--method", "poly3", str(single), "-o", str(tmp_path / f"{channel}.pt")])
            == 0
        )
        alone, _ = load_model(tmp_path / f"{channel}.pt")
        multi, checkpoint = load_model(imu["root"] / "poly3" / f"{channel}.pt")
        assert checkpoint["train_stats"]["channel"] == channel
        view = read_recording(single)
        np.testing.assert_array_equal(multi.predict_drift(view), alone.predict_drift(view))
        lo, hi = checkpoint["valid_temp_range_c"]
        assert (lo, hi) == (float(np.min(view.temp_c)), float(np.max(view.temp_c)))


def test_a_channel_of_many_prints_the_physics_summary_a_one_channel_fit_prints(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The physics structure, its parameters with their spread, its warnings and what the compensator
    carries are printed for each channel of a multi-channel fit, as for the one-channel fit of that
    column (the multi-channel fit once printed none of them, so a flagged parameter went unseen)."""
    single = tmp_path / "gyro0_x.npz"
    write_recording(one_axis(read_recording(imu["rec"]), "gyro0_x"), single)
    forced = ["fit", "--method", "physics", "--effects", "hysteresis_offset", "--quiet"]
    capsys.readouterr()
    assert (
        trainer_main([*forced, str(imu["rec"]), "--channels", "gyro0_x", "-o", str(tmp_path / "many")]) == 0
    )
    many = capsys.readouterr().out
    assert trainer_main([*forced, str(single), "-o", str(tmp_path / "one.pt")]) == 0
    one = capsys.readouterr().out

    def summary(out: str) -> list[str]:
        return [line for line in out.splitlines() if line.startswith(("physics structure", "  "))]

    assert summary(many) and summary(many) == summary(one)
    assert any(
        line.strip().startswith("compensates: bias_poly + hysteresis_offset") for line in summary(many)
    )
    assert "amp_dps" in "\n".join(summary(many))  # in the channel's unit


def test_evaluate_per_channel_reports_in_the_channel_unit(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = read_recording(imu["rec"])
    out = tmp_path / "ev"
    assert trainer_main(["evaluate", str(imu["root"] / "poly3"), str(imu["rec"]), "--channels", "gyro0_x,accel0_y",
                         "--out-dir", str(out), "--smoothing", "0"]) == 0  # fmt: skip
    multi = capsys.readouterr().out
    for channel, unit in (("gyro0_x", "deg/s"), ("accel0_y", "mg")):
        single = tmp_path / f"{channel}.npz"
        write_recording(one_axis(rec, channel), single)
        assert trainer_main(["evaluate", str(imu["root"] / "poly3" / f"{channel}.pt"), str(single),
                             "--out-dir", str(tmp_path / channel), "--smoothing", "0"]) == 0  # fmt: skip
        line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("drift left"))
        expected = line.replace(" mg", f" {unit}")
        assert expected in multi.splitlines()
        report = (out / channel / "report.md").read_text()
        assert f" {unit}" in report and (unit == "mg" or " mg" not in report)


def test_evaluate_one_channel_model_on_the_multi_channel_file_scores_its_own_channel(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A gyro0_x model given the whole IMU file (no --channels) scores gyro0_x in deg/s, exactly as
    on a file holding that channel alone, never the file's accel_mg (it did: mg figures of accel z)."""
    rec = read_recording(imu["rec"])
    model = str(imu["root"] / "poly3" / "gyro0_x.pt")
    single = tmp_path / "gyro0_x.npz"
    write_recording(one_axis(rec, "gyro0_x"), single)
    lines = []
    for source, out in ((imu["rec"], "multi"), (single, "single")):
        assert trainer_main(["evaluate", model, str(source), "--out-dir", str(tmp_path / out),
                             "--smoothing", "0"]) == 0  # fmt: skip
        lines.append(next(x for x in capsys.readouterr().out.splitlines() if x.startswith("drift left")))
    assert " deg/s" in lines[0] and " mg" not in lines[0].replace("true_drift_mg", "")
    assert lines[0] == lines[1]


def test_verify_of_one_channel_module_on_the_multi_channel_file_reads_its_own_channel(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """codegen verify of a gyro0_x module given the whole IMU file streams gyro0_x: its error budget
    (sensor noise included) is the one-axis file's, in deg/s (it used the accel_mg column's noise)."""
    rec = read_recording(imu["rec"])
    model = str(imu["root"] / "poly3" / "gyro0_x.pt")
    single = tmp_path / "gyro0_x.npz"
    write_recording(one_axis(rec, "gyro0_x"), single)
    assert codegen_main(["export", model, "-o", str(tmp_path / "c")]) == 0
    capsys.readouterr()
    budgets = []
    for source in (imu["rec"], single):
        assert codegen_main(["verify", model, str(tmp_path / "c"), str(source), "--no-table"]) == 0
        budgets.append(next(x for x in capsys.readouterr().out.splitlines() if x.startswith("error budget")))
    assert budgets[0] == budgets[1] and " deg/s" in budgets[0] and " mg" not in budgets[0]


def test_a_channel_model_on_a_recording_without_its_channel_is_refused_in_one_line(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """evaluate and verify of a gyro0_x model on an accelerometer-only recording: one line naming the
    model's channel, exit 2, nothing written (they scored the accel_mg column)."""
    rec = read_recording(imu["rec"])
    accel = tmp_path / "accel.npz"
    write_recording(one_axis(rec, "accel0_x"), accel)
    model = str(imu["root"] / "poly3" / "gyro0_x.pt")
    assert codegen_main(["export", model, "-o", str(tmp_path / "c")]) == 0
    capsys.readouterr()
    for cli, args in (
        (trainer_main, ["evaluate", model, str(accel), "--out-dir", str(tmp_path / "ev")]),
        (
            codegen_main,
            ["verify", model, str(tmp_path / "c"), str(accel), "--json", str(tmp_path / "v.json")],
        ),
    ):
        code = run_cli(cli, args)
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and "no channel 'gyro0_x'" in err, err
    assert not (tmp_path / "ev").exists() and not (tmp_path / "v.json").exists()


def test_a_model_on_a_one_axis_import_of_another_axis_is_refused_in_one_line(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An accel0_x model on the one-axis import of accel0_z (metadata channel=accel0_z, the same
    unit): evaluate and report scored z with x's cubic, titled accel0_x; verify likewise."""
    rec = read_recording(imu["rec"])
    z_only = one_axis(rec, "accel0_z")
    z_only.meta["channel"] = "accel0_z"  # what trainer import of that one axis writes
    z_file = tmp_path / "z.csv"
    write_recording(z_only, z_file)
    model = str(imu["root"] / "poly3" / "accel0_x.pt")
    assert codegen_main(["export", model, "-o", str(tmp_path / "c")]) == 0
    capsys.readouterr()
    for cli, args in (
        (trainer_main, ["evaluate", model, str(z_file), "--out-dir", str(tmp_path / "ev")]),
        (trainer_main, ["report", model, "--recording", str(z_file), "-o", str(tmp_path / "so")]),
        (
            codegen_main,
            ["verify", model, str(tmp_path / "c"), str(z_file), "--json", str(tmp_path / "v.json")],
        ),
    ):
        code = run_cli(cli, args)
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1, err
        assert "its accel_mg is channel accel0_z" in err and "is of accel0_x" in err, err
    assert not any((tmp_path / p).exists() for p in ("ev", "so", "v.json"))
    # the model of that axis is scored as before
    z_model = str(imu["root"] / "poly3" / "accel0_z.pt")
    assert run_cli(trainer_main, ["evaluate", z_model, str(z_file), "--out-dir", str(tmp_path / "ok")]) == 0


def test_a_misspelled_channel_column_is_refused_not_left_out(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """gyro0_x_dsp (a typo of gyro0_x_dps): --channels all fitted five channels without a word and the
    IMU shipped with gyro x uncompensated. Refused for its sensor; another sensor's list still fits."""
    rec = read_recording(imu["rec"])
    columns = {("gyro0_x_dsp" if k == "gyro0_x_dps" else k): v for k, v in rec.columns.items()}
    typo = tmp_path / "typo.csv"
    write_recording(Recording(columns, dict(rec.meta), "typo"), typo)
    for wanted in ("all", "gyro0_y"):
        out = tmp_path / f"m_{wanted}"
        code = run_cli(
            trainer_main, ["fit", "--method", "poly3", str(typo), "--channels", wanted, "-o", str(out)]
        )
        err = capsys.readouterr().err.strip()
        assert (
            code == 2
            and len(err.splitlines()) == 1
            and "column 'gyro0_x_dsp'" in err
            and "gyro0_x_dps" in err
        )
        assert not out.exists()
    out = tmp_path / "m_accel"
    assert (
        run_cli(
            trainer_main, ["fit", "--method", "poly3", str(typo), "--channels", "accel0_x", "-o", str(out)]
        )
        == 0
    )


def test_a_bad_channel_name_is_one_line_naming_the_available_ones(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = run_cli(trainer_main, ["fit", "--method", "poly3", str(imu["rec"]), "--channels", "accel0_x,gyro0_q",
                                  "-o", str(tmp_path / "m")])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert (
        "'gyro0_q'" in err
        and "available: accel0_x, accel0_y, accel0_z, gyro0_x, gyro0_y, gyro0_z, baro0" in err
    )
    assert not (tmp_path / "m").exists()
    code = run_cli(
        codegen_main,
        ["export", str(imu["root"] / "pla"), "--channels", "accel0_x", "-o", str(tmp_path / "c")],
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "available: gyro0_x, gyro0_y, baro0" in err


def test_all_says_when_the_files_own_accel_mg_is_left_out(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A simulated IMU carries its accelerometer as accel_mg beside gyro0_x_dps: ``all`` (the named
    channels) must not drop it silently; an imported file's accel_mg, a copy of a channel, is no news."""
    rec = read_recording(imu["rec"])
    assert trainer_main(["fit", "--method", "poly3", str(imu["rec"]), "--channels", "all", "-o",
                         str(tmp_path / "copy")]) == 0  # fmt: skip
    assert "left out" not in capsys.readouterr().err
    columns = {k: v for k, v in rec.columns.items() if k in ("time_s", "temp_c", "gyro0_x_dps")}
    columns["accel_mg"] = rec.columns["accel0_x_mg"] + 1.0  # its own column, no named channel equals it
    own = tmp_path / "sim.npz"
    write_recording(Recording(columns, dict(rec.meta), "sim"), own)
    assert (
        trainer_main(["fit", "--method", "poly3", str(own), "--channels", "all", "-o", str(tmp_path / "own")])
        == 0
    )
    notes = [x for x in capsys.readouterr().err.splitlines() if "left out" in x]
    assert len(notes) == 1 and "accel_mg" in notes[0] and "without --channels" in notes[0]
    assert [
        c["channel"] for c in json.loads((tmp_path / "own" / "channels.json").read_text())["channels"]
    ] == ["gyro0_x"]


def test_a_model_directory_without_channels_says_what_to_add(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    models = str(imu["root"] / "poly3")
    for cli, args in (
        (codegen_main, ["export", models, "--format", "px4-params", "-o", str(tmp_path / "p")]),
        (trainer_main, ["evaluate", models, str(imu["rec"])]),
    ):
        code = run_cli(cli, args)
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1
        assert "a directory, not a model file" in err and "--channels all" in err
    assert not (tmp_path / "p").exists()


@pytest.mark.parametrize("damage", ["model lost", "index lost", "index garbled"])
def test_a_model_directory_that_lost_a_file_is_refused_not_exported_short(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], damage: str
) -> None:
    """A copy of a fit directory without gyro0_y.pt exported five channels, its PX4 file with the
    axis's coefficients 0 and the compensation enabled: the index says what the set is."""
    models = tmp_path / "models"
    shutil.copytree(imu["root"] / "poly3", models)
    if damage == "model lost":
        (models / "gyro0_y.pt").unlink()
    elif damage == "index lost":
        (models / "channels.json").unlink()
    else:
        (models / "channels.json").write_text('{"channels": [{"channel": "accel0_x"')
    for cli, args in (
        (
            codegen_main,
            ["export", str(models), "--channels", "all", "--format", "px4-params", "-o", str(tmp_path / "p")],
        ),
        (codegen_main, ["export", str(models), "--channels", "all", "-o", str(tmp_path / "c")]),
        (
            trainer_main,
            ["evaluate", str(models), str(imu["rec"]), "--channels", "all", "--out-dir", str(tmp_path / "e")],
        ),
    ):
        code = run_cli(cli, args)
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1, err
        assert {"model lost": "gyro0_y.pt is not there", "index lost": "no channels.json",
                "index garbled": "not the index"}[damage] in err  # fmt: skip
    assert not any((tmp_path / d).exists() for d in "pce")


def test_a_refit_of_fewer_channels_exports_only_those(imu: dict[str, Path], tmp_path: Path) -> None:
    """A model of an earlier, wider fit left in the directory is not part of the set the index lists."""
    models = tmp_path / "models"
    shutil.copytree(imu["root"] / "poly3", models)
    index = json.loads((models / "channels.json").read_text())
    index["channels"] = [c for c in index["channels"] if c["channel"] != "gyro0_z"]
    (models / "channels.json").write_text(json.dumps(index))
    assert run_cli(codegen_main, ["export", str(models), "--channels", "all", "-o", str(tmp_path / "c")]) == 0
    manifest = json.loads(next((tmp_path / "c").glob("*.manifest.json")).read_text())
    assert "gyro0_z" not in json.dumps(manifest) and "gyro0_y" in json.dumps(manifest)


def test_refusals_say_why(imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = run_cli(trainer_main, ["fit", "--method", "dlstm", str(imu["rec"]), "--channels", "baro0", "-o",
                                  str(tmp_path / "d")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and "baro0" in err and "recursive" in err and "altitude" in err


def test_compare_and_diagnose_per_channel_outputs(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cmp"
    argv = [
        "compare",
        str(imu["rec"]),
        "--holdout",
        "0.5",
        "--methods",
        "poly3",
        "--channels",
        "gyro0_x,baro0",
    ]
    assert trainer_main([*argv, "--out-dir", str(out), "--quiet"]) == 0
    for channel, unit in (("gyro0_x", "deg/s"), ("baro0", "Pa")):
        report = (out / channel / "report.md").read_text()
        assert f"drift left RMS ({unit})" in report and "(mg)" not in report
        # the paper's accelerometer figures are not set beside this channel's (they came relabelled:
        # "of its gyro: 5.43e-4 milli-g"), and the report says why
        assert "5.43e-4" not in report and "Improvements next to the paper" not in report
        assert "The paper's Table 1 is of another kind of sensor" in report
        assert "gyro:" not in report and "baro:" not in report
        assert load_checkpoint(out / channel / "models" / "poly3.pt")["train_stats"]["channel"] == channel
    code = run_cli(
        trainer_main, [*argv[:-1], "baro0", "--methods", "dlstm,poly3", "--out-dir", str(tmp_path / "x")]
    )
    assert code == 2 and "recursive" in capsys.readouterr().err and not (tmp_path / "x").exists()
    (tmp_path / "j").mkdir()
    argv = ["diagnose", str(imu["rec"]), "--channels", "accel0_x", "--json", str(tmp_path / "j" / "d.json")]
    assert trainer_main(argv) == 0
    assert json.loads((tmp_path / "j" / "d.accel0_x.json").read_text())


def _mixed_models(imu: dict[str, Path]) -> list[Path]:
    """poly3 on accelerometer and gyro z, pla on gyro x/y and the barometer."""
    pla = {"gyro0_x", "gyro0_y", "baro0"}
    return [imu["root"] / ("pla" if c in pla else "poly3") / f"{c}.pt" for c in (*CHANNELS, "baro0")]


def test_imu_module_is_bit_exact_against_each_channel_golden_model(
    imu: dict[str, Path], tmp_path: Path
) -> None:
    models = _mixed_models(imu)
    out = tmp_path / "c"
    assert codegen_main(["export", *map(str, models), "-o", str(out), "--name", "imu0"]) == 0
    wide = read_recording(imu["wide"])
    for cc in ("gcc", "clang"):  # strict warnings are errors with both
        if shutil.which(cc) is None:
            continue
        result = verify_imu(models, out, wide, cc=cc)
        assert [run.target for run in result.runs] == ["host"]
        assert result.runs[0].mismatches == [0] * 7 and result.runs[0].state_equal
    # the golden flags saw the out-of-range temperatures; the C agrees on them (state_equal)
    model = load_imu(models)
    raw, temp = step_inputs(model, wide)
    _, flags, samples = imu_golden(model, raw, temp)
    assert samples == len(wide) and all(f & 1 for f in flags)
    # identical files for identical models (determinism)
    again = tmp_path / "again"
    assert codegen_main(["export", *map(str, reversed(models)), "-o", str(again), "--name", "imu0"]) == 0
    for name in ("imu0.h", "imu0.c", "imu0.manifest.json"):
        assert (out / name).read_bytes() == (again / name).read_bytes()
    header = (out / "imu0.h").read_text()
    assert (
        "gyro0_x [deg/s], pla" in header and "baro0 [Pa], pla" in header and "accel0_z [mg], poly3" in header
    )
    # the rate contract's macros are there for memoryless channels too (any rate): firmware that checks
    # its rate compiles against this module as against one built for a rate; a rate of 0 does not
    strict = ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Wconversion", "-Wshadow", "-Werror", "-c"]
    for rate, compiles in (("200000u", True), ("0u", False)):
        check = tmp_path / f"check_{rate}.c"
        check.write_text(f'#include "imu0.h"\nIMU0_CHECK_SAMPLE_RATE_MILLIHZ({rate});\nint imu0_user;\n')
        built = subprocess.run(
            ["gcc", *strict, f"-I{out}", str(check), "-o", str(tmp_path / "check.o")], capture_output=True
        )
        assert (built.returncode == 0) == compiles, built.stderr.decode()


def test_imu_module_under_sanitizers_saturates_and_flags(imu: dict[str, Path], tmp_path: Path) -> None:
    models = _mixed_models(imu)
    out = tmp_path / "c"
    assert codegen_main(["export", *map(str, models), "-o", str(out), "--name", "imu0"]) == 0
    model = load_imu(models)
    rng = np.random.default_rng(9)
    n = 400
    raw = rng.integers(-(2**31), 2**31, size=(n, 7), dtype=np.int64).astype(np.int32)
    raw[:100:2], raw[1:100:2] = (
        np.iinfo(np.int32).max,
        np.iinfo(np.int32).min,
    )  # a drift of either sign saturates
    temp = rng.integers(-300_000, 300_000, size=(n, 3)).astype(np.int32)
    ffi, lib = load_host_module(
        out, "imu0", flags=("-O1", "-fsanitize=undefined", "-fno-sanitize-recover=all")
    )
    state = ffi.new("imu0_state_t *")
    lib.imu0_init(state, lib.imu0_builtin())
    c_out = np.empty_like(raw)
    for k in range(n):
        o = ffi.new("int32_t[7]")
        lib.imu0_step(
            state,
            ffi.from_buffer("int32_t[]", raw[k].copy()),
            ffi.from_buffer("int32_t[]", temp[k].copy()),
            o,
        )
        c_out[k] = list(o)
    g_out, g_flags, g_samples = imu_golden(model, raw, temp)
    np.testing.assert_array_equal(c_out.astype(np.int64), g_out)
    assert list(state.flags) == g_flags and state.samples == g_samples
    assert all(f & 4 for f in g_flags)  # saturation happened on every channel and is flagged


def _reseal(blob: bytes) -> bytes:
    return blob[:-4] + struct.pack("<I", zlib.crc32(blob[:-4]))


def test_blob_round_trip_and_refusals(imu: dict[str, Path], tmp_path: Path) -> None:
    models = _mixed_models(imu)
    out = tmp_path / "c"
    assert codegen_main(["export", *map(str, models), "-o", str(out), "--name", "imu0", "--blob"]) == 0
    blob = (out / "imu0.cal.bin").read_bytes()
    model = load_imu(models)
    assert blob == encode_blob(model)
    # the documented layout, read independently: header, then sensors, then channel records, CRC32
    magic, version, channels, sensors, capacity, module_id, sha = BLOB_HEADER.unpack_from(blob, 0)
    assert (magic, version, channels, sensors) == (b"TDCC", 1, 7, 3) and capacity == 4
    assert sha.hex() == model.sha256 and module_id == model.module_id
    assert struct.unpack("<I", blob[-4:])[0] == zlib.crc32(blob[:-4])
    first = BLOB_HEADER.size + 8 * sensors
    kind, sensor, *_ = CHANNEL_HEADER.unpack_from(blob, first)
    assert (kind, sensor) == (1, 0)  # accel0_x: a cubic on the first sensor

    ffi, lib = load_host_module(out, "imu0")
    assert "imu0_builtin" not in dir(lib)  # data-only module
    cal = ffi.new("imu0_calibration_t *")
    assert lib.imu0_load(cal, ffi.from_buffer("uint8_t[]", blob), len(blob)) == 0
    assert bytes(cal.sha256) == bytes.fromhex(model.sha256)
    result = verify_imu(models, out, read_recording(imu["wide"]))
    assert [(r.calibration, sum(r.mismatches), r.state_equal) for r in result.runs] == [("blob", 0, True)]

    corrupted = bytearray(blob)
    corrupted[first + 30] ^= 0x01
    version_2 = bytearray(blob)
    version_2[4] = 2
    other_module = bytearray(blob)
    other_module[12] ^= 0xFF
    bad_shift = bytearray(blob)
    bad_shift[first + 3] = 40  # u_shift of a cubic beyond what its arithmetic is proved for
    cases = {
        4: bytes(corrupted),  # CRC
        3: _reseal(bytes(version_2)),  # layout version
        5: _reseal(bytes(other_module)),  # module id
        6: _reseal(bytes(bad_shift)),  # table bounds
        1: blob[:20],  # too short
    }
    for status, data in cases.items():
        cal = ffi.new("imu0_calibration_t *")
        assert lib.imu0_load(cal, ffi.from_buffer("uint8_t[]", data), len(data)) == status
        assert not any(bytes(ffi.buffer(cal))), "a refused blob leaves the calibration zeroed"


def test_imu_module_on_cortex_m4(imu: dict[str, Path], tmp_path: Path) -> None:
    if shutil.which("arm-none-eabi-gcc") is None or shutil.which("qemu-system-arm") is None:
        pytest.skip("Cortex-M toolchain unavailable")
    models = _mixed_models(imu)
    out = tmp_path / "c"
    assert codegen_main(["export", *map(str, models), "-o", str(out), "--name", "imu0"]) == 0
    shutil.copy(out / "imu0.c", tmp_path / "keep.c")
    assert (
        codegen_main(
            ["export", *map(str, models), "-o", str(out), "--format", "calibration-blob", "--name", "imu0"]
        )
        == 0
    )
    result = verify_imu(models, out, read_recording(imu["wide"]), cortex_m4=True)
    assert [(r.target, r.calibration) for r in result.runs] == [
        ("host", "builtin"), ("cortex-m4", "builtin"), ("host", "blob"), ("cortex-m4", "blob")
    ]  # fmt: skip
    assert all(sum(r.mismatches) == 0 and r.state_equal for r in result.runs)


def test_import_real_run_keeps_accelerometer_and_gyroscope(tmp_path: Path, real_run: Path) -> None:
    out = tmp_path / "real.npz"
    assert (
        trainer_main(["import", str(real_run), "--preset", "tofupilot", "--channels", "all", "-o", str(out)])
        == 0
    )
    rec = read_recording(out)
    raw = np.genfromtxt(real_run, delimiter="\t", names=True, max_rows=50)
    np.testing.assert_allclose(rec.columns["gyro0_x_dps"][:50], raw["imugyrox"] * 180 / np.pi, rtol=1e-12)
    np.testing.assert_allclose(rec.columns["accel0_y_mg"][:50], raw["imuaccy"] / 9.80665 * 1000, rtol=1e-12)
    assert "accel_x_mg" not in rec.columns  # the channels replace the older spelling


def test_a_gyro_channel_carries_its_unit_into_checkpoint_and_header(
    imu: dict[str, Path], tmp_path: Path
) -> None:
    stats = load_checkpoint(imu["root"] / "poly3" / "gyro0_y.pt")["train_stats"]
    assert stats["channel"] == "gyro0_y" and stats["unit"] == "dps"
    assert (
        codegen_main(
            ["export", str(imu["root"] / "poly3" / "gyro0_y.pt"), "-o", str(tmp_path), "--name", "g"]
        )
        == 0
    )
    header = " ".join((tmp_path / "g.h").read_text().replace(" * ", " ").split())  # unwrapped comment
    assert "channel gyro0_y: values in deg/s" in header and "16000 LSB = 1 deg/s" in header


# --------------------------------------------------------------------------- flight logs
from tests.data_io.test_flightlog_import import dataflash, ulog_data, ulog_path  # noqa: E402, F401  (fixtures)


def test_flight_log_channels_keep_what_was_asked_on_one_time_base(
    tmp_path: Path,
    dataflash: tuple[Path, dict],  # noqa: F811 (the fixture imported above)
    ulog_path: Path,  # noqa: F811
    capsys: pytest.CaptureFixture[str],
) -> None:
    from trainer.data.channels import recording_channels

    path, _ = dataflash
    out = tmp_path / "df.npz"
    assert (
        trainer_main(["import", str(path), "--channel", "accel1_z", "--channels", "all", "-o", str(out)]) == 0
    )
    # one recording per time base: the test log writes both IMUs at the same timestamps (one file),
    # the barometers at their own
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "df_accel0-accel1-gyro0-gyro1.npz",
        "df_baro0-baro1.npz",
    ]
    rec = read_recording(tmp_path / "df_accel0-accel1-gyro0-gyro1.npz")
    expected = [f"{s}{i}_{a}" for s in ("accel", "gyro") for i in (0, 1) for a in "xyz"]
    assert list(recording_channels(rec)) == expected
    assert recording_channels(rec)["gyro1_x"].temp_column == "gyro1_temp_c"
    assert rec.meta["channel"] == "accel1_z"
    assert list(recording_channels(read_recording(tmp_path / "df_baro0-baro1.npz"))) == ["baro0", "baro1"]

    out = tmp_path / "ulog.npz"
    assert trainer_main(["import", str(ulog_path), "--channels", "accel0_x,accel0_z", "-o", str(out)]) == 0
    assert list(recording_channels(read_recording(out))) == ["accel0_x", "accel0_z"]
    code = run_cli(
        trainer_main,
        [
            "import",
            str(ulog_path),
            "--channel",
            "accel0_z",
            "--channels",
            "accel0_x,gyro0_x",
            "-o",
            str(tmp_path / "x.npz"),
        ],
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "--channel 'accel0_z' is not among --channels (accel0_x, gyro0_x)" in err
    assert not list(tmp_path.glob("x*.npz"))


def test_channel_map_of_a_delimited_file_converts_each_sensor_unit(tmp_path: Path) -> None:
    n = 40
    temp = 20.0 + 0.25 * np.arange(n)
    ax, gx, p = 0.01 * np.arange(n), 0.001 * np.arange(n), 1013.0 + 0.01 * np.arange(n)
    lines = ["t;T;ax;gx;p"] + [f"{0.1 * i:.1f};{temp[i]};{ax[i]};{gx[i]};{p[i]}" for i in range(n)]
    source = tmp_path / "log.csv"
    source.write_text("\n".join(lines) + "\n")
    out = tmp_path / "rec.npz"
    argv = ["import", str(source), "--time", "t", "--temp", "T", "--accel", "ax", "--accel-unit", "g"]
    argv += ["--channel-map", "accel0_x=ax,gyro0_x=gx,baro0=p", "--gyro-unit", "rad/s", "--baro-unit", "hPa"]
    assert trainer_main([*argv, "--channels", "all", "-o", str(out)]) == 0
    rec = read_recording(out)
    np.testing.assert_allclose(rec.columns["accel0_x_mg"], ax * 1000.0, rtol=1e-12)
    np.testing.assert_allclose(rec.columns["gyro0_x_dps"], np.degrees(gx), rtol=1e-12)
    np.testing.assert_allclose(rec.columns["baro0_pa"], p * 100.0, rtol=1e-12)


@pytest.mark.parametrize(("mapped", "given", "option"), [
    ("gyro0_x=gx", ["--baro-unit", "hPa"], "--gyro-unit rad/s|dps"),
    ("baro0=p", ["--gyro-unit", "rad/s"], "--baro-unit Pa|hPa"),
])  # fmt: skip
def test_a_mapped_gyroscope_or_barometer_needs_its_unit_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], mapped: str, given: list[str], option: str
) -> None:
    """A gyroscope in rad/s imported as deg/s (the default it had) is 57x too small and plausible:
    a channel the user maps takes its unit from the user, in one line otherwise, nothing written."""
    lines = ["t;T;ax;gx;p"] + [
        f"{0.1 * i:.1f};{20 + 0.25 * i};{0.01 * i};{0.001 * i};1013" for i in range(40)
    ]
    source = tmp_path / "log.csv"
    source.write_text("\n".join(lines) + "\n")
    argv = [
        "import",
        str(source),
        "--time",
        "t",
        "--temp",
        "T",
        "--accel",
        "ax",
        "--accel-unit",
        "mg",
        "--channel-map",
        mapped,
    ]
    assert run_cli(trainer_main, [*argv, *given, "--channels", "all", "-o", str(tmp_path / "rec.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and option in err and mapped.split("=")[0] in err
    assert not (tmp_path / "rec.csv").exists()


def _without(rec: Recording, *names: str, temps: dict[str, np.ndarray] | None = None) -> Recording:
    columns = {k: v for k, v in rec.columns.items() if k not in names}
    return Recording({**columns, **(temps or {})}, dict(rec.meta), rec.source)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_a_multi_channel_file_may_leave_out_the_one_axis_columns(
    imu: dict[str, Path], tmp_path: Path, suffix: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The contract's "Several channels": ``accel_mg`` and ``temp_c`` are optional beside named
    channels (each channel then reads its own ``<sensor><instance>_temp_c``). Such a file is fitted
    per channel exactly as the file with them; a one-channel command without ``--channels`` says
    which channels there are, in one line, and writes nothing."""
    rec = read_recording(imu["rec"])
    own = {f"{sensor}0_temp_c": rec.temp_c for sensor in ("accel", "gyro")}
    path = tmp_path / f"channels{suffix}"
    write_recording(_without(rec, "accel_mg", "temp_c", temps=own), path)
    assert (
        trainer_main(["fit", "--method", "poly3", str(path), "--channels", "all", "-o", str(tmp_path / "m")])
        == 0
    )
    for channel in (*CHANNELS, "baro0"):
        mine, _ = load_model(tmp_path / "m" / f"{channel}.pt")
        theirs, _ = load_model(imu["root"] / "poly3" / f"{channel}.pt")
        view = one_axis(rec, channel, "baro0_temp_c" if channel == "baro0" else "temp_c")
        np.testing.assert_array_equal(mine.predict_drift(view), theirs.predict_drift(view))
    capsys.readouterr()
    assert run_cli(trainer_main, ["fit", "--method", "poly3", str(path), "-o", str(tmp_path / "one.pt")]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no column 'accel_mg'" in err and "--channels" in err, err
    assert "gyro0_x" in err and not (tmp_path / "one.pt").exists()


def test_a_channel_without_any_temperature_is_refused_naming_it(imu: dict[str, Path], tmp_path: Path) -> None:
    """Without ``temp_c``, a channel that has no temperature column of its own cannot be read."""
    rec = read_recording(imu["rec"])
    path = tmp_path / "no-temp.csv"
    columns = {k: v for k, v in rec.columns.items() if k != "temp_c"}
    columns["accel0_temp_c"] = rec.temp_c  # the gyroscope keeps none
    text = "\n".join(
        [
            f"# sample_rate_hz={RATE_HZ:g}",
            ",".join(columns),
            *(",".join(f"{v:.6f}" for v in row) for row in zip(*columns.values(), strict=True)),
        ]
    )
    path.write_text(text + "\n")
    with pytest.raises(
        UserError, match=r"line 2 \(header\), column 'temp_c': missing: channel gyro0_x has no"
    ):
        read_recording(path)


def test_two_spellings_of_one_channel_must_agree(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`accel_y_mg` (the older spelling) beside `accel0_y_mg` 100 mg apart: one was dropped without a
    word; now a refusal naming both. The same data under both names is one channel, read once."""
    n = 300
    temp = np.linspace(-10, 50, n)
    for offset, code in ((100.0, 2), (0.0, 0)):
        columns = {"time_s": np.arange(n, dtype=float), "temp_c": temp, "accel_y_mg": 0.05 * temp}
        columns["accel0_y_mg"] = 0.05 * temp + offset
        path = tmp_path / f"both{code}.csv"
        write_recording(Recording(columns, {"sample_rate_hz": "1"}, "both"), path)
        out = tmp_path / f"fit{code}"
        argv = ["fit", "--method", "poly3", str(path), "--channels", "all", "-o", str(out)]
        assert run_cli(trainer_main, argv) == code
        if code:
            err = capsys.readouterr().err
            assert (
                "'accel_y_mg' and 'accel0_y_mg' are two spellings of one channel" in err and not out.exists()
            )
        else:
            assert sorted(p.name for p in out.glob("*.pt")) == ["accel0_y.pt"]


def test_a_one_channel_fit_of_a_multi_channel_file_says_which_column_it_fits(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An import of ``--channels gyro0_z`` still holds the preset's accelerometer axis in accel_mg (the
    format requires the column): a fit without --channels fitted that axis and exported it as an
    accelerometer calibration, unsaid."""
    rec = read_recording(imu["rec"])
    columns = {k: v for k, v in rec.columns.items() if k in ("time_s", "temp_c", "accel_mg", "gyro0_z_dps")}
    write_recording(Recording(columns, dict(rec.meta), "gz"), tmp_path / "gz.csv")
    capsys.readouterr()
    assert (
        trainer_main(["fit", "--method", "poly3", str(tmp_path / "gz.csv"), "-o", str(tmp_path / "gz.pt")])
        == 0
    )
    notes = [line for line in capsys.readouterr().err.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and "accel_mg (accel0_z)" in notes[0] and "carries gyro0_z" in notes[0]
    one = tmp_path / "one.csv"
    write_recording(one_axis(rec, "accel0_x"), one)
    assert trainer_main(["fit", "--method", "poly3", str(one), "-o", str(tmp_path / "one.pt")]) == 0
    assert "note:" not in capsys.readouterr().err  # nothing else to fit


def test_channels_with_a_model_file_name_is_refused_not_made_a_directory(
    imu: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recording, model_file = str(imu["rec"]), str(tmp_path / "y7.pt")
    argv = ["fit", "--method", "poly3", recording, "--channels", "gyro0_x", "-o", model_file]
    assert run_cli(trainer_main, argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--channels writes a directory of models" in err
    assert not (tmp_path / "y7.pt").exists()


def test_a_gyroscope_module_speaks_of_angular_rate_in_its_own_unit(
    imu: dict[str, Path], tmp_path: Path
) -> None:
    """A gyroscope's C module said "acceleration in and out ... 1/16 micro-g, range +-134 g" and took
    ``accel_q4ug``; its header, argument names and run function now say the channel's own words."""
    assert (
        codegen_main(
            ["export", str(imu["root"] / "poly3" / "gyro0_x.pt"), "-o", str(tmp_path), "--name", "gx"]
        )
        == 0
    )
    header = (tmp_path / "gx.h").read_text()
    source = (tmp_path / "gx.c").read_text()
    assert "angular rate in and out int32 in 1/16000 deg/s" in header
    assert "int32_t gx_step(gx_state_t *state, int32_t rate_q16k, int32_t temp_mdegc);" in header
    for text in (header, source):
        assert "accel_q4ug" not in text and "micro-g" not in text and "acceleration" not in text
        assert "accel LSB" not in text and "1/16 ug" not in text  # the coefficients' comment too
    flags = ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Wconversion", "-Wshadow", "-Werror", "-c"]
    built = subprocess.run(
        ["gcc", *flags, "gx.c", "-o", "gx.o"], cwd=tmp_path, capture_output=True, text=True
    )
    assert built.returncode == 0 and not built.stderr, built.stderr
