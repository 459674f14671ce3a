"""An IMU module (docs/imu-module.md) enters a sign-off: ``trainer report --verify DIR`` runs
``codegen verify --channels`` on it once for every model given, and ``codegen verify --channels
--json F`` writes F, which ``trainer report --verify F`` reads; each model gets its own channel's
mismatches, and a model the module was not exported from is refused in one line."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest

from codegen.cli import main as codegen_main
from tests.data_io.test_channels import imu_recording
from trainer.cli import main as trainer_main
from trainer.data.recording_io import write_recording
from trainer.errors import run_cli

CHANNELS = ("accel0_z", "gyro0_x")


@pytest.fixture(scope="module")
def module(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("imu_signoff")
    write_recording(imu_recording(n=600), root / "imu.csv")
    fit = ["fit", "--method", "poly3", str(root / "imu.csv"), "--channels", ",".join(CHANNELS)]
    assert trainer_main([*fit, "-o", str(root / "fit")]) == 0
    assert codegen_main(["export", str(root / "fit"), "--channels", "all", "-o", str(root / "imu_c")]) == 0
    return {"root": root, "rec": root / "imu.csv", "fit": root / "fit", "out": root / "imu_c"}


def _verify_lines(report: Path) -> dict[str, str]:
    """Channel section -> its codegen verify line, read from report.md."""
    lines: dict[str, str] = {}
    section = ""
    for line in report.read_text().splitlines():
        if line.startswith("## ") and "/" in line:
            section = line[3:].split(" / ")[0].removeprefix("Channel ").strip()
        if line.startswith("- codegen verify"):
            lines[section] = line
    return lines


def test_codegen_verify_channels_writes_its_json(module: dict[str, Path], tmp_path: Path) -> None:
    path = tmp_path / "v.json"
    argv = ["verify", str(module["fit"]), str(module["out"]), str(module["rec"]), "--channels", "all"]
    assert codegen_main([*argv, "--json", str(path)]) == 0
    data = json.loads(path.read_text())
    assert [c["name"] for c in data["channels"]] == list(CHANNELS)
    for channel in data["channels"]:
        digest = hashlib.sha256((module["fit"] / f"{channel['name']}.pt").read_bytes()).hexdigest()
        assert channel["model_id"] == f"sha256:{digest}" and channel["mismatches"] == 0
    assert data["samples"] == 600 and data["state_equal"] is True and data["mismatches"] == 0


def test_report_verifies_an_imu_module_for_every_model(module: dict[str, Path], tmp_path: Path) -> None:
    models = [str(module["fit"] / f"{c}.pt") for c in CHANNELS]
    out = tmp_path / "s"
    argv = [
        "report",
        *models,
        "--recording",
        str(module["rec"]),
        "--verify",
        str(module["out"]),
        "-o",
        str(out),
    ]
    assert run_cli(trainer_main, argv) == 0
    lines = _verify_lines(out / "report.md")
    assert set(lines) == set(CHANNELS)
    assert all("0 mismatches in 600 samples" in line for line in lines.values()), lines


def test_report_reads_the_imu_json_per_channel(module: dict[str, Path], tmp_path: Path) -> None:
    path = tmp_path / "v.json"
    argv = ["verify", str(module["fit"]), str(module["out"]), str(module["rec"]), "--channels", "all"]
    assert codegen_main([*argv, "--json", str(path)]) == 0
    data = json.loads(path.read_text())
    data["channels"][1]["mismatches"] = 7  # as if gyro0_x's output had differed on 7 samples
    path.write_text(json.dumps(data))
    models = [str(module["fit"] / f"{c}.pt") for c in CHANNELS]
    out = tmp_path / "s"
    argv = ["report", *models, "--recording", str(module["rec"]), "--verify", str(path), "-o", str(out)]
    run_cli(trainer_main, argv)
    lines = _verify_lines(out / "report.md")
    assert "0 mismatches in 600 samples" in lines["accel0_z"]
    assert "7 mismatches in 600 samples" in lines["gyro0_x"]


def test_a_model_outside_the_module_is_refused(
    module: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    other = tmp_path / "fit"
    shutil.copytree(module["fit"], other)
    argv = [
        "fit",
        "--method",
        "pla",
        str(module["rec"]),
        "--channels",
        "accel0_z",
        "-o",
        str(tmp_path / "pla"),
    ]
    assert trainer_main(argv) == 0
    shutil.copy(tmp_path / "pla" / "accel0_z.pt", other / "accel0_z.pt")  # not the module's model
    capsys.readouterr()
    argv = [
        "report",
        str(other / "gyro0_x.pt"),
        str(other / "accel0_z.pt"),
        "--recording",
        str(module["rec"]),
    ]
    assert run_cli(trainer_main, [*argv, "--verify", str(module["out"]), "-o", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "accel0_z" in err and str(module["out"]) in err
    assert not (tmp_path / "s").exists()


def test_codegen_verify_channels_with_the_recording_and_the_module_swapped_says_so(
    module: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # as the one-model form does (docs/recordings.md), not "unsupported extension" of the module's directory
    json_path = tmp_path / "v.json"
    argv = ["verify", str(module["fit"]), str(module["rec"]), str(module["out"]), "--channels", "all"]
    capsys.readouterr()
    assert run_cli(codegen_main, [*argv, "--json", str(json_path)]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"error: {module['rec']}: a recording, not the generated module's directory (arguments swapped? the "
        "order is model out_dir recording)\n"
    )
    assert not json_path.exists()
