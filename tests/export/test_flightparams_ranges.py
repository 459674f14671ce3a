"""Where a flight-stack file corrects less than the model covers, the file and the terminal say so:
a shared range narrower than a channel's own, and ArduPilot's declared TMIN/TMAX range."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from tests.export.test_flightparams import (
    DEVICE_ID,
    G,
    ardupilot_correction,
    fit,
    model_drift,
    read_ardupilot_parm,
    read_px4_params,
)
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import UserError


def run_over(path: Path, channel: str, low_c: float, high_c: float, seed: int) -> Path:
    """A 1 Hz cycle low -> high -> low + 10 degC with a cubic drift."""
    rng = np.random.default_rng(seed)
    temp = np.concatenate([np.linspace(low_c, high_c, 900), np.linspace(high_c, low_c + 10.0, 700)])
    d = temp - 20.0
    drift = 5.0 + 0.3 * d - 0.004 * d**2 + 2e-5 * d**3 + rng.normal(0, 0.05, temp.size)
    meta = {"sample_rate_hz": "1", "channel": channel, "device_id_accel0": str(DEVICE_ID)}
    write_recording(
        Recording({"time_s": np.arange(temp.size, dtype=float), "temp_c": temp, "accel_mg": drift}, meta),
        path,
    )
    return path


def test_a_shared_range_narrower_than_a_channels_own_is_said_in_the_file_and_on_the_terminal(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wide = fit(run_over(tmp_path / "x.csv", "accel0_x", -20.0, 60.0, 1), tmp_path / "x.pt")
    narrow = fit(run_over(tmp_path / "y.csv", "accel0_y", -20.0, 40.0, 2), tmp_path / "y.pt")
    capsys.readouterr()
    assert (
        codegen_main(
            ["export", str(wide), str(narrow), "--format", "px4-params", "-o", str(tmp_path / "px4")]
        )
        == 0
    )
    out = capsys.readouterr().out
    text = (tmp_path / "px4" / "px4_thermal.params").read_text()
    params = read_px4_params(tmp_path / "px4" / "px4_thermal.params")
    assert params["TC_A0_TMAX"] == pytest.approx(40.0, abs=0.01)
    said = "accel0_x: fitted over -20.00 .. 60.00 degC, corrected over -20.00 .. 40.00 degC only"
    assert said in out and said in text
    assert "accel0_y: fitted over" not in out  # its own range is the shared one


def test_ardupilot_tmax_above_its_declared_range_is_written_at_80_and_said(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    hot = fit(run_over(tmp_path / "hot.csv", "accel0_x", -30.0, 100.0, 3), tmp_path / "hot.pt")
    capsys.readouterr()
    assert codegen_main(["export", str(hot), "--format", "ardupilot-parm", "-o", str(tmp_path / "ap")]) == 0
    out = capsys.readouterr().out
    params = read_ardupilot_parm(tmp_path / "ap" / "ardupilot_tcal.parm")
    assert params["INS_TCAL1_TMIN"] == pytest.approx(-30.0, abs=0.01) and params["INS_TCAL1_TMAX"] == 80.0
    assert "leaves ArduPilot's declared -70 .. 80 degC; written as -30.00 .. 80.00" in out
    # inside the written range ArduPilot applies the model (relative to CALTEMP); above it, the 80 degC value
    temp = np.linspace(-30.0, 100.0, 1301)
    drift, drift_range = model_drift(hot, temp)
    at_cal, _ = model_drift(hot, np.array([35.0]))
    applied = ardupilot_correction(params, 0, "ACC", "X", temp, 35.0).astype(float) * 1000.0 / G
    held = np.where(temp > 80.0, model_drift(hot, np.array([80.0]))[0][0], drift)
    np.testing.assert_allclose(applied, held - at_cal[0], rtol=0, atol=1e-5 * drift_range)


def test_device_id_is_refused_for_ardupilot_which_applies_by_imu_index(tmp_path: Path) -> None:
    model = fit(run_over(tmp_path / "x.csv", "accel0_x", -20.0, 60.0, 4), tmp_path / "x.pt")
    argv = [
        "export",
        str(model),
        "--format",
        "ardupilot-parm",
        "--device-id",
        "accel0=5",
        "-o",
        str(tmp_path / "ap"),
    ]
    with pytest.raises(UserError, match="apply by IMU index"):
        codegen_main(argv)
    assert not (tmp_path / "ap").exists()
