"""Flight-stack parameters of several sensor instances: what PX4 would do with the file decides.

PX4 (TemperatureCompensation::set_sensor_id) applies to a sensor the first TC_An set whose TC_An_ID
equals its device id, and TC_A_ENABLE switches every accelerometer instance; so two sets under one
id leave a sensor uncompensated, and sets the file does not carry stay active as the vehicle has
them. A model moved to another axis with --channel, and sensors of several devices sharing one
temperature column, are said where the user reads them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import UserError

PX4_ACCEL_SETS = 4  # TC_A0..TC_A3 (ACCEL_COUNT_MAX in PX4's TemperatureCompensation.h)


def chamber(path: Path, columns: dict[str, float], meta: dict[str, str]) -> Path:
    """A 1 Hz chamber run, -20 -> 60 -> -10 degC; each named column a cubic drift of its own slope."""
    rng = np.random.default_rng(7)
    temp = np.concatenate([np.linspace(-20, 60, 900), np.linspace(60, -10, 700)])
    d = temp - 20.0
    data = {"time_s": np.arange(temp.size, dtype=float), "temp_c": temp}
    for column, slope in columns.items():
        data[column] = slope * d - 0.004 * d**2 + rng.normal(0, 0.05, temp.size)
    write_recording(Recording(data, {"sample_rate_hz": "1", **meta}), path)
    return path


@pytest.fixture(scope="module")
def two_accels(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """poly3 models of accel0_x and accel1_x (one directory, as trainer fit --channels writes it)."""
    root = tmp_path_factory.mktemp("two")
    rec = chamber(root / "r.csv", {"accel_mg": 0.3, "accel0_x_mg": 0.3, "accel1_x_mg": -0.2}, {})
    assert (
        trainer_main(["fit", "--method", "poly3", str(rec), "--channels", "all", "-o", str(root / "m")]) == 0
    )
    return root / "m"


def export(out: Path, models: Path, *extra: str) -> Path:
    argv = ["export", str(models), "--channels", "all", "-o", str(out), "--format", "px4-params", *extra]
    assert codegen_main(argv) == 0
    (written,) = out.iterdir()
    return written


def refused(out: Path, models: Path, *extra: str) -> str:
    argv = ["export", str(models), "--channels", "all", "-o", str(out), "--format", "px4-params", *extra]
    with pytest.raises(UserError) as caught:
        codegen_main(argv)
    assert not out.exists()
    return str(caught.value)


def px4_ids(path: Path) -> dict[str, int]:
    fields = [line.split("\t") for line in path.read_text().splitlines() if not line.startswith("#")]
    return {name: int(value) for _, _, name, value, _ in fields if name.endswith("_ID")}


def test_two_instances_under_one_device_id_are_refused(tmp_path: Path, two_accels: Path) -> None:
    message = refused(tmp_path / "same", two_accels, "--device-id", "accel0=11,accel1=11")
    assert "accel0 and accel1 both have device id 11" in message and "\n" not in message
    ids = px4_ids(export(tmp_path / "distinct", two_accels, "--device-id", "accel0=11,accel1=12"))
    assert ids == {"TC_A0_ID": 11, "TC_A1_ID": 12}


def test_a_sensor_given_twice_in_device_id_is_refused(tmp_path: Path, two_accels: Path) -> None:
    message = refused(tmp_path / "o", two_accels, "--device-id", "accel0=5,accel1=6,accel0=7")
    assert message.endswith("--device-id: accel0 is given twice")  # not the last one silently


def test_the_sets_the_file_does_not_carry_are_named(
    tmp_path: Path, two_accels: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = export(tmp_path / "p", two_accels, "--device-id", "accel0=11,accel1=12").read_text()
    carried = {int(name[4]) for name in px4_ids(tmp_path / "p" / "px4_thermal.params")}
    others = [f"TC_A{i}" for i in range(PX4_ACCEL_SETS) if i not in carried]
    note = next(line for line in text.splitlines() if line.startswith("# note: TC_A"))
    assert note.startswith(f"# note: {', '.join(others)}: not in this file")
    assert "TC_A_ENABLE 1" in note
    assert note.removeprefix("# note: ") in capsys.readouterr().out  # the terminal says it too


def test_a_model_moved_to_another_axis_is_said(
    tmp_path: Path, two_accels: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = two_accels / "accel0_x.pt"
    argv = ["export", str(model), "-o", str(tmp_path / "o"), "--format", "px4-params", "--device-id", "5"]
    assert codegen_main([*argv, "--channel", "accel0_z"]) == 0
    out = capsys.readouterr().out
    assert "accel0_z: the model was fitted on accel0_x, written as accel0_z (--channel)" in out
    assert codegen_main([*argv[:3], str(tmp_path / "same"), *argv[4:], "--channel", "accel0_x"]) == 0
    assert "fitted on" not in capsys.readouterr().out  # its own axis: nothing to say


def test_sensors_of_two_devices_sharing_temp_c_are_said(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    one_imu = chamber(tmp_path / "imu.csv", {"accel_mg": 0.3, "accel0_x_mg": 0.3, "gyro0_x_dps": 0.01}, {})
    assert (
        trainer_main(
            ["fit", "--method", "poly3", str(one_imu), "--channels", "all", "-o", str(tmp_path / "a")]
        )
        == 0
    )
    assert "fitted against temp_c" not in capsys.readouterr().err  # one IMU: its temperature
    two = chamber(tmp_path / "two.csv", {"accel_mg": 0.3, "accel0_x_mg": 0.3, "accel1_x_mg": 0.2}, {})
    assert (
        trainer_main(["fit", "--method", "poly3", str(two), "--channels", "all", "-o", str(tmp_path / "b")])
        == 0
    )
    err = capsys.readouterr().err
    assert "accel0_x, accel1_x: fitted against temp_c" in err and "accel1_temp_c" in err
