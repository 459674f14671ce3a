"""``codegen verify`` names an implausible sample by the file's own column and line.

On a multi-channel recording with 5000 dps in ``gyro0_x_dps``, verify of the gyro x module said
``column 'accel_mg', data row 4``: the one-channel view's name, not the file's. It must name the
file's column and line as ``trainer report`` names them for the same file (the same trainer check,
not a copy of it). The expected line number is found by reading the file's text.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from codegen.cli import main as codegen_main
from tests.imu_checks import accel_gyro_columns
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import run_cli

BAD = 5000.0  # dps: beyond any MEMS gyroscope's range
ROW = 4  # the data row (from 1) that holds it


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("file_column")
    columns = accel_gyro_columns(8)
    meta = {"sample_rate_hz": "2", "channel": "accel0_z"}
    write_recording(Recording(columns, meta, "good"), root / "good.csv")
    gyro = columns["gyro0_x_dps"].copy()
    gyro[ROW - 1] = BAD
    write_recording(Recording({**columns, "gyro0_x_dps": gyro}, meta, "bad"), root / "bad.csv")
    fit = [
        "fit",
        "--method",
        "poly3",
        str(root / "good.csv"),
        "--channels",
        "gyro0_x",
        "-o",
        str(root / "fit"),
    ]
    assert trainer_main(fit) == 0
    assert (
        run_cli(
            codegen_main, ["export", str(root / "fit" / "gyro0_x.pt"), "-o", str(root / "c"), "--name", "gx"]
        )
        == 0
    )
    assert (
        run_cli(codegen_main, ["export", str(root / "fit"), "--channels", "all", "-o", str(root / "imu")])
        == 0
    )
    return {"root": root, "bad": root / "bad.csv"}


def _line_of_bad_value(path: Path) -> int:
    """The file's line (from 1) of the row holding BAD in column gyro0_x_dps, read from its text."""
    lines = path.read_text().splitlines()
    header = next(k for k, line in enumerate(lines) if line.startswith("time_s,"))
    column = lines[header].split(",").index("gyro0_x_dps")
    (found,) = [
        k + 1
        for k, line in enumerate(lines[header + 1 :], header + 1)
        if float(line.split(",")[column]) == BAD
    ]
    return found


def _error(capsys: pytest.CaptureFixture[str], main: object, *argv: str) -> str:
    capsys.readouterr()
    assert run_cli(main, list(argv)) == 2  # type: ignore[arg-type]
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def _where(err: str) -> tuple[str, str]:
    found = re.search(r"column '([^']+)', (line \d+|data row \d+)", err)
    assert found is not None, err
    return found.group(1), found.group(2)


def test_verify_names_the_file_s_column_and_line_as_trainer_report_does(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    root, bad = files["root"], str(files["bad"])
    line = _line_of_bad_value(files["bad"])
    assert line > ROW  # the file's line, not the data row: comments and the header come first
    verify_err = _error(
        capsys, codegen_main, "verify", str(root / "fit" / "gyro0_x.pt"), str(root / "c"), bad
    )
    assert _where(verify_err) == ("gyro0_x_dps", f"line {line}")
    assert "accel_mg" not in verify_err and "5000 dps" in verify_err
    report_err = _error(
        capsys,
        trainer_main,
        "report",
        str(root / "fit" / "gyro0_x.pt"),
        "--recording",
        bad,
        "-o",
        str(root / "rep"),
    )
    assert _where(report_err) == _where(verify_err)


def test_the_imu_module_s_verify_names_them_too(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    root = files["root"]
    err = _error(
        capsys,
        codegen_main,
        "verify",
        str(root / "fit"),
        str(root / "imu"),
        str(files["bad"]),
        "--channels",
        "all",
    )
    assert _where(err) == ("gyro0_x_dps", f"line {_line_of_bad_value(files['bad'])}")


def test_verify_json_names_the_unit_as_the_manifest_does(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """The JSON's error budget is in the channel's unit, spelt as the module's manifest spells it
    (``deg/s``), not by the column suffix (``dps``) a program reading both would not match."""
    import json

    root = files["root"]
    out = root / "gx-verify.json"
    argv = [
        "verify",
        str(root / "fit" / "gyro0_x.pt"),
        str(root / "c"),
        str(root / "good.csv"),
        "--json",
        str(out),
    ]
    assert run_cli(codegen_main, argv) == 0
    capsys.readouterr()
    manifest = json.loads((root / "c" / "gx.manifest.json").read_text())
    assert manifest["input_limits"]["input"]["unit"] == "deg/s"
    assert json.loads(out.read_text())["error_budget"]["unit"] == manifest["input_limits"]["input"]["unit"]
    imu_out = root / "imu-verify.json"
    argv = [
        "verify",
        str(root / "fit"),
        str(root / "imu"),
        str(root / "good.csv"),
        "--channels",
        "all",
        "--json",
        str(imu_out),
    ]
    assert run_cli(codegen_main, argv) == 0
    capsys.readouterr()
    assert {c["name"]: c["unit"] for c in json.loads(imu_out.read_text())["channels"]} == {"gyro0_x": "deg/s"}
