"""An output path that would destroy an input, or names a file where a directory goes, is one line
before any work: `trainer diagnose --json` once overwrote the recording it read, and `--channels`
with an existing file as the output directory ended in a FileExistsError traceback."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.data_io.test_channels import imu_recording
from trainer.cli import main as trainer_main
from trainer.data.recording_io import write_recording
from trainer.errors import run_cli


@pytest.fixture
def files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(tmp_path)
    write_recording(imu_recording(n=400), tmp_path / "imu.csv")
    (tmp_path / "victim.csv").write_text("keep me\n")
    return tmp_path


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["diagnose", "imu.csv", "--json", "imu.csv"], "is also the input imu.csv"),
        (["diagnose", "imu.csv", "--channels", "accel0_z", "--json", "imu.csv"], "a recording's name (.csv) for the JSON"),
        (["diagnose", "imu.csv", "--report", "victim.csv"], "victim.csv: exists and is not a directory"),
        (["diagnose", "imu.csv", "--channels", "accel0_z", "--report", "victim.csv"], "exists and is not a directory"),
        (["compare", "imu.csv", "--holdout", "0.3", "--methods", "poly3", "--channels", "gyro0_z", "--out-dir", "victim.csv"], "exists and is not a directory"),
    ],
)  # fmt: skip
def test_a_bad_output_path_is_one_line_and_the_inputs_stay(
    files: Path, argv: list[str], said: str, capsys: pytest.CaptureFixture[str]
) -> None:
    before = {name: (files / name).read_bytes() for name in ("imu.csv", "victim.csv")}
    assert run_cli(trainer_main, argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err and "Traceback" not in err
    assert {name: (files / name).read_bytes() for name in before} == before
    assert sorted(p.name for p in files.iterdir()) == ["imu.csv", "victim.csv"]


def test_a_new_report_directory_gets_the_usual_mode_not_0700(files: Path) -> None:
    """Staged in a mkdtemp directory (0700), a report or a per-channel comparison was unreadable to a
    reviewer on a shared machine; it gets 0777 less the umask, as every other output does."""
    import os
    import stat

    previous = os.umask(0o022)
    try:
        argv = [
            "compare",
            "imu.csv",
            "--holdout",
            "0.3",
            "--methods",
            "poly3",
            "--channels",
            "gyro0_z",
            "--out-dir",
            "cmp",
        ]
        assert run_cli(trainer_main, argv) == 0
    finally:
        os.umask(previous)
    for directory in (files / "cmp", files / "cmp" / "gyro0_z"):
        assert stat.S_IMODE(directory.stat().st_mode) == 0o755, directory
