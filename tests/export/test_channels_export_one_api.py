"""``codegen export DIR --channels LIST`` renders the IMU module whatever the number of channels.

``--channels accel0_z`` gave a one-channel module (``NAME_step(state, accel_q4ug, temp)``) and the same
with ``--blob`` the IMU module, so ``codegen verify ... --channels accel0_z`` found "no IMU module" and
a factory script got two APIs. The expected API is the IMU module's as docs/imu-module.md declares it.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from codegen.cli import main as codegen_main
from tests.imu_checks import accel_gyro_columns
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import run_cli

IMU_FORMAT = "mems-tdc-imu-module"  # docs/imu-module.md: the IMU module's manifest
IMU_STEP = re.compile(  # docs/imu-module.md: one step call for every channel, arrays in and out
    r"void imu_tdc_step\(imu_tdc_state_t \*state, const int32_t \*raw, const int32_t \*temp_mdegc, int32_t \*out\);"
)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("one_api")
    columns = accel_gyro_columns(4)
    write_recording(
        Recording(columns, {"sample_rate_hz": "2", "channel": "accel0_z"}, "one-api"), root / "rec.csv"
    )
    argv = ["fit", "--method", "poly3", str(root / "rec.csv"), "--channels", "all", "-o", str(root / "fit")]
    assert trainer_main(argv) == 0
    return root


def _module(out: Path) -> tuple[dict[str, object], str]:
    manifest = json.loads((out / "imu_tdc.manifest.json").read_text())
    return manifest, (out / "imu_tdc.h").read_text()


@pytest.mark.parametrize("channels", ["accel0_z", "gyro0_x", "accel0_z,gyro0_x"])
def test_any_channel_list_gives_the_imu_module_with_or_without_blob(
    channels: str, fitted: Path, tmp_path: Path
) -> None:
    wanted = channels.split(",")
    for blob in ((), ("--blob",)):
        out = tmp_path / f"c{len(blob)}"
        argv = [
            "export",
            str(fitted / "fit"),
            "--channels",
            channels,
            "-o",
            str(out),
            "--name",
            "imu_tdc",
            *blob,
        ]
        assert run_cli(codegen_main, argv) == 0
        manifest, header = _module(out)
        assert manifest["format"] == IMU_FORMAT
        assert [c["name"] for c in manifest["channels"]] == wanted  # type: ignore[union-attr]
        assert IMU_STEP.search(" ".join(header.split())), blob
        assert "accel_q4ug" not in header


def test_a_one_channel_imu_module_verifies_with_its_channel_list(
    fitted: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "imu_one"
    fit, rec = str(fitted / "fit"), str(fitted / "rec.csv")
    assert (
        run_cli(codegen_main, ["export", fit, "--channels", "accel0_z", "-o", str(out), "--name", "imu_tdc"])
        == 0
    )
    capsys.readouterr()
    assert run_cli(codegen_main, ["verify", fit, str(out), rec, "--channels", "accel0_z"]) == 0
    report = capsys.readouterr().out
    assert "imu_tdc: 1 channel x 1200 samples" in report and "0 mismatches (accel0_z 0)" in report


def test_a_one_channel_module_is_still_exported_from_the_model_file(fitted: Path, tmp_path: Path) -> None:
    """The way to a one-channel module: the model file itself (docs/imu-module.md)."""
    out = tmp_path / "one"
    assert (
        run_cli(
            codegen_main, ["export", str(fitted / "fit" / "accel0_z.pt"), "-o", str(out), "--name", "one"]
        )
        == 0
    )
    manifest = json.loads((out / "one.manifest.json").read_text())
    assert manifest["format"] != IMU_FORMAT
    assert (
        "int32_t one_step(one_state_t *state, int32_t accel_q4ug, int32_t temp_mdegc);"
        in (out / "one.h").read_text()
    )


def test_parameter_file_options_are_refused_for_the_imu_module(
    fitted: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--channel names the channel of a parameter file; given for the C module it was ignored there."""
    argv = [
        "export",
        str(fitted / "fit"),
        "--channels",
        "accel0_z",
        "--channel",
        "accel0_x",
        "-o",
        str(tmp_path / "c"),
    ]
    capsys.readouterr()
    assert run_cli(codegen_main, argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--channel applies to --format" in err
    assert not (tmp_path / "c").exists()


def test_the_imu_export_says_per_channel_what_its_one_channel_export_says(
    fitted: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The constant each channel removes (gravity stays in accel z's output) was printed by the
    one-channel export only: the IMU module's export said nothing of it."""
    capsys.readouterr()
    argv = ["export", str(fitted / "fit"), "--channels", "accel0_z,gyro0_x", "-o", str(tmp_path / "imu")]
    assert run_cli(codegen_main, argv) == 0
    imu_lines = capsys.readouterr().out.splitlines()[1:]
    for channel in ("accel0_z", "gyro0_x"):
        one = ["export", str(fitted / "fit" / f"{channel}.pt"), "-o", str(tmp_path / channel)]
        assert run_cli(codegen_main, one) == 0
        notes = [line.removeprefix("poly3: ") for line in capsys.readouterr().out.splitlines()[1:]]
        offset = next(note for note in notes if note.startswith("offset: drift relative to T_ref"))
        assert f"{channel}: {offset}" in imu_lines
        assert len([line for line in imu_lines if line.startswith(f"{channel}: ")]) == len(notes)
