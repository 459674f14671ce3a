"""Impossible data is refused by import, fit and export (``--accept-implausible`` the only way past)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from trainer.cli import main
from trainer.data.flightlog import SENSOR_RANGES, SENSOR_UNITS
from trainer.data.plausibility import TEMP_MAX_C, TEMP_MIN_C
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import UserError, run_cli

ROWS = 600


def logger_file(path: Path, *, temp: str | None = None, accel: str | None = None) -> Path:
    """t, T, a at 1 Hz, T from -20 to 40 degC; row 100 (data row 101) may hold a given text."""
    lines = ["t,T,a"]
    for k in range(ROWS):
        t_c, a_ms2 = -20.0 + k / 10.0, 0.01 * k / ROWS
        cells = [f"{k}", f"{t_c:.2f}", f"{a_ms2:.5f}"]
        if k == 100:
            cells[1] = temp or cells[1]
            cells[2] = accel or cells[2]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")
    return path


def import_error(source: Path, out: Path, *extra: str) -> str:
    argv = ["import", str(source), "--time", "t", "--temp", "T", "--accel", "a", "--accel-unit", "m/s^2"]
    with pytest.raises(UserError) as caught:
        main([*argv, *extra, "-o", str(out)])
    assert not out.exists()
    return str(caught.value)


@pytest.mark.parametrize(
    ("temp", "accel", "expected"),
    [
        # the source file's own column and line (the header is line 1): not the recording's accel_mg, row 101
        ("-500", None, f"column 'T', line 102: temperature down to -500 degC is below {TEMP_MIN_C:g} degC"),
        ("151", None, f"column 'T', line 102: temperature up to 151 degC is above {TEMP_MAX_C:g} degC"),
        (None, "1e308", "column 'a', line 102: inf mg is outside"),
        (None, "3.3e2", "column 'a', line 102: 3.365e+04 mg is outside the -32000 .. 32000 mg"),  # 33.7 g
    ],
)
def test_import_refuses_impossible_samples(
    temp: str | None, accel: str | None, expected: str, tmp_path: Path
) -> None:
    source = logger_file(tmp_path / "log.csv", temp=temp, accel=accel)
    message = import_error(source, tmp_path / "rec.csv")
    assert expected in message and "--accept-implausible" in message


@pytest.mark.parametrize(
    ("text", "name"), [("\uff11.5", "FULLWIDTH DIGIT ONE"), ("1.5\u00a0", "NO-BREAK SPACE")]
)
def test_non_ascii_numbers_are_refused(text: str, name: str, tmp_path: Path) -> None:
    source = logger_file(tmp_path / "log.csv", accel=text)
    message = import_error(source, tmp_path / "rec.csv", "--accept-implausible")
    assert message.startswith(f"{source}: line 102, column 'a':") and name in message


def test_accept_implausible_passes_and_warns(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    source = logger_file(tmp_path / "log.csv", temp="-500")
    out = tmp_path / "rec.csv"
    argv = ["import", str(source), "--time", "t", "--temp", "T", "--accel", "a", "--accel-unit", "m/s^2"]
    assert run_cli(main, [*argv, "--accept-implausible", "-o", str(out)]) == 0
    assert "warning: " in capsys.readouterr().err and out.exists()


def recording(temp_c: np.ndarray, columns: dict[str, np.ndarray] | None = None) -> Recording:
    n = temp_c.size
    base = {"time_s": np.arange(n, dtype=float), "temp_c": temp_c, "accel_mg": 0.1 * temp_c}
    return Recording({**base, **(columns or {})}, {"sample_rate_hz": "1"}, "rec")


def test_fit_refuses_what_import_refuses_and_export_refuses_the_model(tmp_path: Path) -> None:
    """A recording with one -500 degC sample (written by hand, past import): fit refuses it; a model
    fitted past the check anyway has a valid range whose flag could never fire: export refuses."""
    temp = np.linspace(-20.0, 40.0, ROWS)
    temp[100] = -500.0
    rec_path = tmp_path / "rec.npz"
    write_recording(recording(temp), rec_path)
    model = tmp_path / "m.pt"
    with pytest.raises(UserError, match="below -60 degC"):
        main(["fit", "--method", "poly3", str(rec_path), "-o", str(model)])
    assert not model.exists()
    assert (
        run_cli(main, ["fit", "--method", "poly3", str(rec_path), "-o", str(model), "--accept-implausible"])
        == 0
    )
    out = tmp_path / "c"
    with pytest.raises(
        UserError, match=r"'valid_temp_range_c' -500 \.\. 40 degC is outside the -100 \.\. 200 degC"
    ):
        codegen_main(["export", str(model), "-o", str(out)])
    assert not out.exists()


@pytest.mark.parametrize("sensor", ["gyro", "baro"])
def test_each_channel_against_its_sensor(sensor: str, tmp_path: Path) -> None:
    """A channel beyond its sensor's declared range (here 10 % past it) is refused by fit."""
    column = "gyro0_x_dps" if sensor == "gyro" else "baro0_pa"
    temp = np.linspace(-20.0, 40.0, ROWS)
    values = np.full(ROWS, np.mean(SENSOR_RANGES[sensor]))
    values[7] = SENSOR_RANGES[sensor][1] * 1.1
    rec_path = tmp_path / "rec.npz"
    write_recording(recording(temp, {column: values}), rec_path)
    channel = "gyro0_x" if sensor == "gyro" else "baro0"
    unit = SENSOR_UNITS[sensor]
    lo, hi = SENSOR_RANGES[sensor]
    with pytest.raises(UserError, match=rf"data row 8: \S+ {unit} is outside the {lo:g} \.\. {hi:g} {unit}"):
        main(["fit", "--method", "poly3", str(rec_path), "--channels", channel, "-o", str(tmp_path / "m")])


def test_a_csv_channel_s_refusal_names_its_column_and_line(tmp_path: Path) -> None:
    """A multi-channel CSV (metadata lines above the header): fit of the channel named the view's
    'accel_mg' or another axis and counted data rows; the file's column and line are named now."""
    temp = np.linspace(-20.0, 40.0, ROWS)
    values = np.full(ROWS, 1.0)
    values[7] = 1e5
    path = tmp_path / "rec.csv"
    write_recording(recording(temp, {"gyro0_x_dps": values, "accel0_x_mg": 0.1 * temp}), path)
    line = next(n for n, text in enumerate(path.read_text().splitlines(), start=1) if "100000" in text)
    for channels in (["--channels", "gyro0_x"], ["--channels", "all"]):
        with pytest.raises(UserError, match=rf"column 'gyro0_x_dps', line {line}: 1e\+05 dps is outside"):
            main(["fit", "--method", "poly3", str(path), *channels, "-o", str(tmp_path / "m")])
