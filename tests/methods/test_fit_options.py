"""``trainer fit`` refuses an option of another method (``--effects`` with poly3, ``--remove-median``
with physics, a DLSTM's ``--temp-smoothing`` with poly3) instead of ignoring it: the user expected
it to act. Options of the fitted method and the command-wide ``--quiet`` pass."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_corpus import valid_lines
from trainer.cli import main as trainer_main
from trainer.errors import run_cli


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--method", "poly3", "--effects", "thermal_lag"], "--effects does not apply to --method poly3: it is an option of physics"),
        (["--method", "physics", "--remove-median"], "--remove-median does not apply to --method physics: it is an option of poly3"),
        (["--method", "poly3", "--temp-smoothing", "-3", "--step", "0"], "--temp-smoothing does not apply to --method poly3: it is an option of dlstm"),
        (["--method", "auto", "--intervals", "3"], "--intervals does not apply to --method auto: it is an option of pla"),
        (["--method", "poly3", "--remove-median", "--quiet"], None),
        (["--method", "pla", "--intervals", "3"], None),
    ],
)  # fmt: skip
def test_an_option_of_another_method_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str | None
) -> None:
    rec = tmp_path / "rec.csv"
    rec.write_text("\n".join(valid_lines()) + "\n")
    out = tmp_path / "m.pt"
    code = run_cli(trainer_main, ["fit", *argv, str(rec), "-o", str(out)])
    err = capsys.readouterr().err
    if message is None:
        assert code == 0 and out.is_file()
    else:
        assert code == 2 and message in err and err.count("\n") == 1 and not out.exists()


def _ramp_csv(path: Path, outlier_c: float | None = None) -> Path:
    rows = ["time_s,temp_c,accel_mg"]
    for i in range(1000):
        temp = 40.0 * i / 999
        if outlier_c is not None and i == 500:
            temp = outlier_c
        rows.append(f"{i},{temp!r},{0.1 * temp + 0.001 * temp**2 if temp < 100 else 1.0!r}")
    path.write_text("\n".join(rows) + "\n")
    return path


def test_a_method_refusal_names_the_recording_and_the_likely_cause(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One 5e9 degC reading let through with --accept-implausible: the cubic's bins then hold two
    temperatures. The line names the file and says the range was stretched (it said only "poly3:
    fewer than 4 distinct temperatures")."""
    rec = _ramp_csv(tmp_path / "outlier.csv", outlier_c=5e9)
    argv = ["fit", "--method", "poly3", str(rec), "-o", str(tmp_path / "m.pt"), "--accept-implausible"]
    assert run_cli(trainer_main, argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {rec}: poly3: fewer than 4 distinct temperatures after averaging")
    assert "outlying temperatures stretch the range" in err and "\n" not in err
    assert not (tmp_path / "m.pt").exists()


def test_the_model_does_not_depend_on_how_the_recording_s_path_was_typed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`imu.csv`, `./imu.csv` and `/abs/imu.csv`: the same data, the same model file byte for byte
    (and so the same NAME_model_id() in the firmware)."""
    _ramp_csv(tmp_path / "ramp.csv")
    monkeypatch.chdir(tmp_path)
    for k, path in enumerate(("ramp.csv", "./ramp.csv", str(tmp_path / "ramp.csv"))):
        assert run_cli(trainer_main, ["fit", "--method", "poly3", path, "-o", f"m{k}.pt", "--quiet"]) == 0
    first = (tmp_path / "m0.pt").read_bytes()
    assert (tmp_path / "m1.pt").read_bytes() == first and (tmp_path / "m2.pt").read_bytes() == first
