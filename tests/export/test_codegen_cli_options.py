"""What ``codegen`` reads from its command line, and says back.

- ``codegen verify ... --channel accel0_z`` was read as ``--channels`` (argparse's prefix matching;
  ``--channel`` is an option of ``export``) and failed on "a directory written by trainer fit".
- ``verify`` of a poly2 model said ``error budget (golden - float, poly3)``: the registered class, not
  the model the header names.
- ``export --channels accel0_z,accel0_z`` wrote a one-channel module without a word.
- a flight-stack export of several models that are not cubics named the first only.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from codegen.cli import main as codegen_main
from tests.cli_capture import run_captured
from tests.imu_checks import accel_gyro_columns
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording

CHANNELS = ("accel0_z", "gyro0_x")  # accel_gyro_columns' channels


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A two-channel recording and three fits of it: poly3, poly2 and pla (ten intervals)."""
    root = tmp_path_factory.mktemp("cli_options")
    rec = root / "rec.csv"
    write_recording(Recording(accel_gyro_columns(8), {"sample_rate_hz": "2"}, "cli-options"), rec)
    for method in ("poly3", "poly2", "pla"):
        argv = ["fit", "--method", method, str(rec), "--channels", "all", "-o", str(root / method)]
        assert trainer_main(argv) == 0
    return root


def _one_line_refusal(code: int, out: str, err: str) -> str:
    lines = err.strip().splitlines()
    assert code == 2 and out == "" and len(lines) == 1 and lines[0].startswith("error: "), (code, out, err)
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize(
    ("command", "given"),
    [
        ("verify", ["--channel", "accel0_z"]),  # --channel is export's; --channels was read
        ("export", ["--form", "px4-params"]),  # --format was read
        ("verify", ["--no-tab"]),  # --no-table was read
    ],
)
def test_a_prefix_of_an_option_is_not_read_as_the_option(
    command: str,
    given: list[str],
    root: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "out"
    positional = (
        [str(root / "poly3" / "accel0_z.pt"), str(out), str(root / "rec.csv")]
        if command == "verify"
        else [str(root / "poly3" / "accel0_z.pt"), "-o", str(out)]
    )
    line = _one_line_refusal(*run_captured(codegen_main, capsys, command, *positional, *given))
    assert f"unrecognized arguments: {' '.join(given)}" in line, line
    assert "directory" not in line and not out.exists()


def test_verify_names_the_model_s_own_method_in_the_error_budget(
    root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = root / "poly2" / "accel0_z.pt"
    out = tmp_path / "p2"
    code, _, err = run_captured(codegen_main, capsys, "export", str(model), "-o", str(out), "--name", "p2")
    assert code == 0, err
    assert 'method "poly2"' in (out / "p2.h").read_text()  # what the header names it
    code, stdout, err = run_captured(
        codegen_main, capsys, "verify", str(model), str(out), str(root / "rec.csv"), "--no-table"
    )
    assert code == 0, err
    budget = [line for line in stdout.splitlines() if line.startswith("error budget (")]
    assert len(budget) == 1 and budget[0].startswith("error budget (golden - float, poly2): "), stdout


@pytest.mark.parametrize("fmt", ["c", "px4-params"])
def test_a_channel_given_twice_is_refused(
    fmt: str, root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "k7"
    args = ["export", str(root / "poly3"), "-o", str(out), "--format", fmt]
    line = _one_line_refusal(
        *run_captured(codegen_main, capsys, *args, "--channels", "accel0_z,gyro0_x,accel0_z")
    )
    assert line.endswith(": accel0_z given twice: list each channel once"), line  # gyro0_x is not repeated
    assert not out.exists()


def test_a_model_file_given_twice_is_refused_by_the_c_export_as_by_the_parameter_files(
    root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = str(root / "poly3" / "accel0_z.pt")
    lines = []
    for fmt in ("c", "px4-params"):
        out = tmp_path / fmt
        args = ["export", model, model, "-o", str(out), "--format", fmt]
        lines.append(_one_line_refusal(*run_captured(codegen_main, capsys, *args)))
        assert not out.exists()
    assert lines[0] == lines[1] == "error: two models for channel accel0_z (accel0_z given twice)"


@pytest.mark.parametrize("fmt", ["px4-params", "ardupilot-parm"])
def test_a_parameter_file_export_names_every_model_that_is_not_a_cubic(
    fmt: str, root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "params"
    line = _one_line_refusal(
        *run_captured(
            codegen_main,
            capsys,
            "export",
            str(root / "pla"),
            "--channels",
            "all",
            "-o",
            str(out),
            "--format",
            fmt,
        )
    )
    for channel in CHANNELS:
        assert f"{channel} (method 'pla', {root / 'pla' / channel}.pt)" in line, line
    assert "not a cubic of the temperature" in line and not out.exists()
    # a cubic among them is not named: only what the user must refit
    line = _one_line_refusal(
        *run_captured(
            codegen_main,
            capsys,
            "export",
            str(root / "poly3" / "accel0_z.pt"),
            str(root / "pla" / "gyro0_x.pt"),
            "-o",
            str(out),
            "--format",
            fmt,
        )
    )
    assert "accel0_z" not in line and f"{root / 'pla' / 'gyro0_x.pt'}: method 'pla'" in line, line
