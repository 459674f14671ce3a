"""An ArduPilot set whose every model is the identity must leave no earlier calibration on the board.

The file wrote ``INS_TCAL1_ENABLE 0`` and zero coefficients; but ArduPilot hides ``INS_TCALn_*`` while
ENABLE is 0 (``AP_PARAM_FLAG_ENABLE``), so the zeros never loaded: the earlier coefficients survived
hidden and applied again once ENABLE was set to 1. The board is modelled here from ArduPilot's
sources (libraries/AP_InertialSensor/AP_InertialSensor_tempcal.cpp):

- a parameter load sets ENABLE and, only if ENABLE was non-zero when the list was read, the others;
- ``correct_sensor`` returns unless ENABLE is 1 (Enabled), else subtracts ``P(clamp(T) - 35)`` and adds
  ``P(clamp(CALTEMP) - 35)``, ``P(d) = (C1 + (C2 + C3 d) d) d * 1e-6``.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from tests.cli_capture import run_captured
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording

RATE_HZ = 2.0
PROFILE = ((50.0, 0.0), (-15.0, 22.0), (-15.0, 1.0), (70.0, 28.0), (35.0, 14.0))  # degC, minutes: a cycle
SET = "INS_TCAL1"
COEFFICIENTS = [f"{SET}_{s}{k}_{a}" for s in ("ACC", "GYR") for k in (1, 2, 3) for a in "XYZ"]


def _temperature() -> np.ndarray:
    temps = [np.array([PROFILE[0][0]])]
    for (start, _), (end, minutes) in itertools.pairwise(PROFILE):
        temps.append(np.linspace(start, end, round(minutes * 60 * RATE_HZ) + 1)[1:])
    return np.concatenate(temps)


@pytest.fixture(scope="module")
def identity_models(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """accel0_z and gyro0_x without drift (noise only): auto leaves both uncompensated."""
    root = tmp_path_factory.mktemp("identity_set")
    temp = _temperature()
    rng = np.random.default_rng(11)
    columns = {
        "time_s": np.arange(temp.size) / RATE_HZ,
        "temp_c": temp,
        "accel0_z_mg": -1000.0 + rng.normal(0.0, 0.05, temp.size),
        "gyro0_x_dps": rng.normal(0.0, 0.01, temp.size),
    }
    columns["accel_mg"] = columns["accel0_z_mg"]
    write_recording(Recording(columns, {"sample_rate_hz": "2"}, "identity"), root / "imu.csv")
    argv = [
        "fit",
        "--method",
        "auto",
        "--candidates",
        "none,poly3",
        str(root / "imu.csv"),
        "--channels",
        "all",
    ]
    assert trainer_main([*argv, "-o", str(root / "m")]) == 0
    return root / "m"


def _parameters(path: Path) -> list[tuple[str, float]]:
    rows = []
    for line in path.read_text().splitlines():
        if line and not line.startswith("#"):
            name, value = line.split(" ")
            rows.append((name, float(value)))
    return rows


def _load(board: dict[str, float], rows: list[tuple[str, float]]) -> None:
    """One parameter-file load: INS_TCAL1_* other than ENABLE are hidden while ENABLE was 0 when read."""
    visible = board[f"{SET}_ENABLE"] != 0
    for name, value in rows:
        if name == f"{SET}_ENABLE" or (name.startswith(f"{SET}_") and visible):
            board[name] = value


def _correction(
    board: dict[str, float], sensor: str, axis: str, temp_c: np.ndarray, cal_c: float
) -> np.ndarray:
    if board[f"{SET}_ENABLE"] != 1:
        return np.zeros_like(temp_c)
    lo, hi = board[f"{SET}_TMIN"], board[f"{SET}_TMAX"]
    c1, c2, c3 = (board[f"{SET}_{sensor}{k}_{axis}"] for k in (1, 2, 3))

    def poly(d: np.ndarray) -> np.ndarray:
        return (c1 + (c2 + c3 * d) * d) * d * 1e-6

    return poly(np.clip(temp_c, lo, hi) - 35.0) - poly(np.clip(np.array([cal_c]), lo, hi) - 35.0)


def test_an_identity_set_overwrites_a_hidden_earlier_calibration(
    identity_models: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "ap"
    code, stdout, err = run_captured(
        codegen_main,
        capsys,
        "export",
        str(identity_models),
        "--channels",
        "all",
        "-o",
        str(out),
        "--format",
        "ardupilot-parm",
    )
    assert code == 0, err
    assert (
        "accel0_z is exported as the identity" in stdout and "gyro0_x is exported as the identity" in stdout
    )
    (parm,) = out.iterdir()
    rows = _parameters(parm)
    assert all(value == 0.0 for name, value in rows if name in COEFFICIENTS)  # the identity's
    # a board with an earlier calibration, switched off (hidden) when the file is loaded
    board = {f"{SET}_ENABLE": 0.0, f"{SET}_TMIN": 0.0, f"{SET}_TMAX": 70.0}
    board |= {name: 100.0 * (k + 1) for k, name in enumerate(COEFFICIENTS)}
    _load(board, rows)  # the file's own instruction: load, refresh, load again, reboot
    _load(board, rows)
    temps = np.linspace(-40.0, 90.0, 261)
    for sensor, axis in itertools.product(("ACC", "GYR"), "XYZ"):
        assert not np.any(_correction(board, sensor, axis, temps, 20.0)), (sensor, axis)
    # and nothing of the earlier calibration is left to come back when ENABLE is set to 1 later
    board[f"{SET}_ENABLE"] = 1.0
    assert all(board[name] == 0.0 for name in COEFFICIENTS)
    # the file and the terminal say what ENABLE 1 with zeros does, and that the file loads twice
    note = [line for line in parm.read_text().splitlines() if line.startswith(f"# note: {SET} ")]
    assert len(note) == 1 and f"{SET}_ENABLE 1 with zero coefficients" in note[0], note
    assert "load the file twice" in note[0] and note[0].removeprefix("# note: ") in stdout
