"""``trainer import``: the real tofupilot chamber file and small synthetic foreign files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from trainer.cli import main
from trainer.data.importer import STANDARD_GRAVITY
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording
from trainer.errors import UserError, run_cli


@pytest.fixture(scope="module")
def real_raw(real_run: Path) -> dict[str, np.ndarray]:
    """The real file read independently of the importer (column name -> values)."""
    names = real_run.read_text().splitlines()[0].split("\t")
    timestamps = np.loadtxt(real_run, delimiter="\t", skiprows=1, usecols=0, dtype=np.int64)
    values = np.loadtxt(real_run, delimiter="\t", skiprows=1)
    raw = {name: values[:, i] for i, name in enumerate(names)}
    raw["timestamp"] = timestamps  # exact integers (microseconds)
    return raw


def run_import(*args: str | Path) -> Recording:
    """Run the CLI and read back its output with the ordinary reader."""
    argv = ["import", *map(str, args)]
    assert main(argv) == 0
    return read_recording(argv[argv.index("-o") + 1])


def import_error(output: Path, *args: str | Path) -> str:
    with pytest.raises(UserError) as caught:
        main(["import", *map(str, args), "-o", str(output)])
    message = str(caught.value)
    assert "\n" not in message
    assert not output.exists()
    assert not [p for p in output.parent.iterdir() if p.name.startswith(f".{output.name}")]
    return message


# --------------------------------------------------------------------------- the real file


def test_real_file_with_preset(tmp_path: Path, real_run: Path, real_raw: dict[str, np.ndarray]) -> None:
    rec = run_import(real_run, "--preset", "tofupilot", "-o", tmp_path / "real.csv")
    assert len(rec) == 8400
    assert rec.temp_c.min() == pytest.approx(-17.6, abs=0.05)
    assert rec.temp_c.max() == pytest.approx(74.0, abs=0.05)
    assert -1000.0 < rec.accel_mg.mean() < -940.0  # z axis, gravity included (level board)
    # retiming keeps every sample: the values are the file's, converted from m/s^2
    np.testing.assert_allclose(rec.accel_mg, real_raw["imu.acc.z"] / STANDARD_GRAVITY * 1000, rtol=1e-9)
    np.testing.assert_allclose(
        rec.columns["accel_x_mg"], real_raw["imu.acc.x"] / STANDARD_GRAVITY * 1000, rtol=1e-9
    )
    np.testing.assert_allclose(rec.temp_c, real_raw["imu.temperature"], rtol=1e-9)
    span_s = (real_raw["timestamp"][-1] - real_raw["timestamp"][0]) * 1e-6
    assert rec.time_s[0] == 0.0
    assert rec.time_s[-1] == pytest.approx(span_s, abs=1e-6)
    np.testing.assert_allclose(np.diff(rec.time_s), span_s / 8399, rtol=1e-5)
    assert rec.meta["license"] == "MIT (c) 2024 tofupilot, see LICENSE.tofupilot"
    assert rec.meta["source"] == real_run.name
    assert "retimed_from" in rec.meta
    assert float(rec.meta["sample_rate_hz"]) == pytest.approx(8399 / span_s, rel=1e-9)
    first_line = (tmp_path / "real.csv").read_text().splitlines()[0]
    assert first_line.startswith("# sample_rate_hz=")


def test_real_file_breaks_the_jitter_rule_at_the_first_late_step(
    tmp_path: Path, real_run: Path, real_raw: dict
) -> None:
    steps = np.diff(real_raw["timestamp"])
    median = np.median(steps)
    first_late_step = int(np.flatnonzero(np.abs(steps - median) > 0.01 * median)[0])
    expected_line = first_late_step + 3  # header is line 1, row i is line i + 2, step i ends at row i + 1
    message = import_error(tmp_path / "real.csv", real_run, "--preset", "tofupilot", "--resample", "none")
    assert f"line {expected_line}, column 'timestamp'" in message
    assert "--resample" in message


def test_real_file_resampled_linearly(tmp_path: Path, real_run: Path, real_raw: dict) -> None:
    rec = run_import(real_run, "--preset", "tofupilot", "--resample", "auto", "-o", tmp_path / "real.npz")
    assert len(rec) == 8400
    assert "resampled_from" in rec.meta
    source_time = (real_raw["timestamp"] - real_raw["timestamp"][0]) * 1e-6
    source_temp = real_raw["imu.temperature"]
    # every interpolated value lies between the two source samples around its time
    right = np.clip(np.searchsorted(source_time, rec.time_s), 1, len(source_time) - 1)
    low = np.minimum(source_temp[right - 1], source_temp[right]) - 1e-9
    high = np.maximum(source_temp[right - 1], source_temp[right]) + 1e-9
    assert np.all((rec.temp_c >= low) & (rec.temp_c <= high))


def test_real_file_with_gravity_removed(tmp_path: Path, real_run: Path, real_raw: dict) -> None:
    rec = run_import(
        real_run, "--preset", "tofupilot", "--remove-gravity", "nominal", "-o", tmp_path / "g.csv"
    )
    expected = real_raw["imu.acc.z"] / STANDARD_GRAVITY * 1000 + 1000.0  # -1 g axis: add 1000 mg back
    np.testing.assert_allclose(rec.accel_mg, expected, rtol=0, atol=1e-6)
    np.testing.assert_allclose(rec.columns["accel_z_mg"].mean(), -968, atol=30)  # extra axes keep gravity


# --------------------------------------------------------------------------- synthetic foreign files


def write_foreign(path: Path, header: list[str], rows: list[list[object]], delimiter: str = ",") -> Path:
    lines = [delimiter.join(header)] + [delimiter.join(str(v) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def logger_file(tmp_path: Path, n: int = 20, delimiter: str = ",", name: str = "log.txt") -> Path:
    """A 100 Hz logger: t in s, temperature, one axis in mg and a text status column."""
    rows = [[f"{1000 + i / 100:.2f}", 20 + i / 10, -1000 + i, "OK", i % 3] for i in range(n)]
    return write_foreign(tmp_path / name, ["t", "T", "az", "status", "n"], rows, delimiter)


BASIC = ["--time", "t", "--temp", "T", "--accel", "az", "--accel-unit", "mg"]


@pytest.mark.parametrize("delimiter", [",", "\t", ";"])
def test_delimiter_is_sniffed(tmp_path: Path, delimiter: str) -> None:
    foreign = logger_file(tmp_path, delimiter=delimiter)
    rec = run_import(foreign, *BASIC, "-o", tmp_path / "out.csv")
    np.testing.assert_allclose(rec.time_s, np.arange(20) / 100, atol=1e-9)
    np.testing.assert_allclose(rec.temp_c, 20 + np.arange(20) / 10)
    np.testing.assert_allclose(rec.accel_mg, -1000 + np.arange(20))
    assert list(rec.columns) == ["time_s", "temp_c", "accel_mg"]
    assert rec.sample_rate_hz == pytest.approx(100, rel=1e-6)


@pytest.mark.parametrize(("flag", "delimiter"), [("tab", "\t"), (";", ";"), ("comma", ",")])
def test_explicit_delimiter(tmp_path: Path, flag: str, delimiter: str) -> None:
    foreign = logger_file(tmp_path, delimiter=delimiter)
    rec = run_import(foreign, *BASIC, "--delimiter", flag, "-o", tmp_path / "out.npz")
    assert len(rec) == 20


def test_wrong_explicit_delimiter_names_the_files_delimiter(tmp_path: Path) -> None:
    message = import_error(
        tmp_path / "out.csv", logger_file(tmp_path, delimiter="\t"), *BASIC, "--delimiter", ";"
    )
    assert "line 1 (header)" in message
    assert "tab-delimited" in message
    assert "--delimiter" in message


def test_wrong_explicit_delimiter_reports_the_missing_column(tmp_path: Path) -> None:
    """A header that splits on neither: the column the options name is missing."""
    message = import_error(
        tmp_path / "out.csv", logger_file(tmp_path, delimiter=" "), *BASIC, "--delimiter", ";"
    )
    assert "no column 't'" in message


def test_undetectable_delimiter(tmp_path: Path) -> None:
    (tmp_path / "one.txt").write_text("t\n0\n1\n")
    assert "--delimiter" in import_error(tmp_path / "out.csv", tmp_path / "one.txt", *BASIC)


@pytest.mark.parametrize(
    ("unit", "raw", "expected_mg"),
    [("m/s^2", 9.80665, 1000.0), ("m/s^2", -4.903325, -500.0), ("g", -0.25, -250.0), ("mg", 12.5, 12.5)],
)
def test_accel_units(tmp_path: Path, unit: str, raw: float, expected_mg: float) -> None:
    rows = [[i * 0.01, 25.0, raw, raw * 2, 0, raw / 4] for i in range(5)]
    foreign = write_foreign(tmp_path / "f.csv", ["t", "T", "a", "x", "y", "z"], rows)
    rec = run_import(foreign, "--time", "t", "--temp", "T", "--accel", "a", "--accel-unit", unit,
                     "--extra-axes", "x,y,z", "-o", tmp_path / "out.csv")  # fmt: skip
    np.testing.assert_allclose(rec.accel_mg, expected_mg, rtol=1e-9)
    np.testing.assert_allclose(rec.columns["accel_x_mg"], 2 * expected_mg, rtol=1e-9)
    np.testing.assert_allclose(rec.columns["accel_y_mg"], 0.0)
    np.testing.assert_allclose(rec.columns["accel_z_mg"], expected_mg / 4, rtol=1e-9)


@pytest.mark.parametrize(
    ("unit", "start", "step"),
    [
        ("s", 1_700_000_000, 0.005),
        ("ms", 123_456, 5),
        ("us", 256_551_281_491_968, 5_000),  # the real file's clock
        ("ns", 1_700_000_000_000_000_000, 5_000_000),  # epoch ns: beyond float64's exact integers
    ],
)
def test_time_units_shift_to_zero(tmp_path: Path, unit: str, start: int, step: float) -> None:
    rows = [[start + i * step, 30.0, 1.0] for i in range(50)]
    foreign = write_foreign(tmp_path / "f.csv", ["time", "temp", "acc"], rows)
    rec = run_import(foreign, "--time", "time", "--time-unit", unit, "--temp", "temp", "--accel", "acc", "--accel-unit", "mg",
                     "-o", tmp_path / "out.csv")  # fmt: skip
    np.testing.assert_allclose(rec.time_s, np.arange(50) * 0.005, atol=1e-6)
    assert rec.sample_rate_hz == pytest.approx(200.0, rel=1e-3)


def test_index_time_from_the_row_number(tmp_path: Path) -> None:
    index_time = ["--time-unit", "index", "--rate", "50"]
    rec = run_import(
        logger_file(tmp_path),
        *index_time,
        "--temp",
        "T",
        "--accel",
        "az",
        "--accel-unit",
        "mg",
        "-o",
        tmp_path / "o.csv",
    )
    np.testing.assert_allclose(rec.time_s, np.arange(20) / 50)
    assert rec.meta["sample_rate_hz"] == "50"


def test_index_time_from_a_counter_column(tmp_path: Path) -> None:
    rows = [[100 + i, 20.0, 0.0] for i in range(10)]
    foreign = write_foreign(tmp_path / "f.csv", ["sample", "temp", "acc"], rows)
    rec = run_import(foreign, "--time", "sample", "--time-unit", "index", "--rate", "4", "--temp", "temp",
                     "--accel", "acc", "--accel-unit", "mg", "-o", tmp_path / "out.csv")  # fmt: skip
    np.testing.assert_allclose(rec.time_s, np.arange(10) / 4)


def test_index_time_needs_a_rate(tmp_path: Path) -> None:
    message = import_error(tmp_path / "o.csv", logger_file(tmp_path), "--time-unit", "index", "--temp", "T",
                           "--accel", "az", "--accel-unit", "mg")  # fmt: skip
    assert "--rate" in message


def test_rate_is_only_for_index_time(tmp_path: Path) -> None:
    assert "--resample" in import_error(tmp_path / "o.csv", logger_file(tmp_path), *BASIC, "--rate", "100")


def test_unknown_column_lists_the_available_ones(tmp_path: Path) -> None:
    message = import_error(tmp_path / "o.csv", logger_file(tmp_path), "--time", "t", "--temp", "temperature",
                           "--accel", "az", "--accel-unit", "mg")  # fmt: skip
    assert "no column 'temperature'" in message
    assert "'t', 'T', 'az', 'status', 'n'" in message
    assert "line 1" in message


def test_non_numeric_cell_names_line_and_column(tmp_path: Path) -> None:
    foreign = logger_file(tmp_path)
    lines = foreign.read_text().splitlines()
    lines[7] = lines[7].replace(",-", ",oops-", 1)  # the az cell of the 7th data row
    foreign.write_text("\n".join(lines) + "\n")
    assert "line 8, column 'az': 'oops-" in import_error(tmp_path / "o.csv", foreign, *BASIC)


def test_nan_cell_is_an_error(tmp_path: Path) -> None:
    rows = [[i / 100, 20.0, "nan" if i == 3 else 1.0] for i in range(6)]
    foreign = write_foreign(tmp_path / "f.csv", ["t", "T", "az"], rows)
    assert "line 5, column 'az'" in import_error(tmp_path / "o.csv", foreign, *BASIC)


def test_time_not_increasing_names_the_line(tmp_path: Path) -> None:
    rows = [[t, 20.0, 1.0] for t in (0.0, 0.01, 0.02, 0.02, 0.03)]
    foreign = write_foreign(tmp_path / "f.csv", ["t", "T", "az"], rows)
    assert "line 5, column 't': 0.02 is not greater" in import_error(tmp_path / "o.csv", foreign, *BASIC)


def jittery_file(tmp_path: Path, lost_sample: bool = False) -> tuple[Path, np.ndarray]:
    """A 10 Hz logger whose sample 6 comes 3 % late (or one sample goes missing); az = 2 * t_ms."""
    time = np.arange(12) * 0.1
    time[6:] += 0.003
    if lost_sample:
        time = np.delete(time, 4)
    rows = [[f"{t:.4f}", 20.0, 2 * t * 1000] for t in time]
    return write_foreign(tmp_path / "j.csv", ["t", "T", "az"], rows), time


def test_jitter_over_one_percent_fails_and_suggests_resampling(tmp_path: Path) -> None:
    foreign, _ = jittery_file(tmp_path)
    message = import_error(tmp_path / "o.csv", foreign, *BASIC)
    assert "line 8, column 't'" in message  # row 6 is the 7th data row
    assert "3.00 %" in message
    assert "--resample HZ" in message


def test_resample_puts_every_column_on_a_uniform_grid(tmp_path: Path) -> None:
    foreign, time = jittery_file(tmp_path)
    rec = run_import(foreign, *BASIC, "--resample", "20", "-o", tmp_path / "o.csv")
    grid = np.arange(np.floor(time[-1] * 20 + 1e-9) + 1) / 20
    np.testing.assert_allclose(rec.time_s, grid, atol=1e-9)
    np.testing.assert_allclose(rec.accel_mg, 2 * grid * 1000, atol=1e-6)  # linear signal: exact
    assert rec.meta["sample_rate_hz"] == "20"
    assert "resampled_from" in rec.meta
    assert "linear" in rec.meta["resampled_from"]


def test_retime_keeps_samples(tmp_path: Path) -> None:
    foreign, time = jittery_file(tmp_path)
    rec = run_import(foreign, *BASIC, "--retime", "-o", tmp_path / "o.csv")
    np.testing.assert_allclose(rec.accel_mg, 2 * time * 1000)
    np.testing.assert_allclose(rec.time_s, np.linspace(0, time[-1], len(time)), atol=5e-7)  # 6 decimals


def test_retime_refuses_a_lost_sample(tmp_path: Path) -> None:
    foreign, _ = jittery_file(tmp_path, lost_sample=True)
    message = import_error(tmp_path / "o.csv", foreign, *BASIC, "--retime")
    assert "line 6, column 't'" in message  # the step over the missing sample ends at row 4
    assert "--resample" in message


def test_retime_and_resample_exclude_each_other(tmp_path: Path) -> None:
    foreign, _ = jittery_file(tmp_path)
    assert "exclude" in import_error(tmp_path / "o.csv", foreign, *BASIC, "--retime", "--resample", "10")


@pytest.mark.parametrize(("offset_mg", "mode", "subtracted"), [(1000.0, "nominal", 1000.0),
                                                               (-1000.0, "nominal", -1000.0),
                                                               (-995.0, "nominal", -1000.0),
                                                               (40.0, "mean", 42.0)])  # fmt: skip
def test_gravity_removal(tmp_path: Path, offset_mg: float, mode: str, subtracted: float) -> None:
    wiggle = np.array([-3.0, 1.0, 4.0, 6.0])  # mean 2
    rows = [[i / 10, 20.0, offset_mg + w] for i, w in enumerate(wiggle)]
    foreign = write_foreign(tmp_path / "f.csv", ["t", "T", "az"], rows)
    rec = run_import(foreign, *BASIC, "--remove-gravity", mode, "-o", tmp_path / "o.csv")
    np.testing.assert_allclose(rec.accel_mg, offset_mg + wiggle - subtracted, atol=1e-9)
    assert mode in rec.meta["gravity_removed"]


def test_nominal_gravity_on_a_horizontal_axis_is_refused(tmp_path: Path) -> None:
    rows = [[i / 10, 20.0, 18.0] for i in range(4)]
    foreign = write_foreign(tmp_path / "f.csv", ["t", "T", "az"], rows)
    message = import_error(tmp_path / "o.csv", foreign, *BASIC, "--remove-gravity", "nominal")
    assert "column 'az'" in message
    assert "not near" in message


def test_metadata_records_the_origin(tmp_path: Path) -> None:
    rec = run_import(logger_file(tmp_path), *BASIC, "--sensor", "board-7", "-o", tmp_path / "o.csv")
    assert rec.meta["sensor"] == "board-7"
    assert rec.meta["source"] == "log.txt"
    assert "accel_mg<-az[mg]" in rec.meta["mapping"]
    assert "license" not in rec.meta


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--temp", "T", "--accel", "az", "--accel-unit", "mg"], "--time"),
        (["--time", "t", "--accel", "az", "--accel-unit", "mg"], "--temp"),
        ([*BASIC, "--resample", "fast"], "--resample"),
        ([*BASIC, "--extra-axes", "a,b"], "--extra-axes"),
        ([*BASIC, "--delimiter", "|"], "--delimiter"),
        ([*BASIC, "--preset", "nope"], "--preset"),
        # no default unit: an axis in m/s^2 read as mg passes every range check, 100x too small
        (
            ["--time", "t", "--temp", "T", "--accel", "az"],
            "--accel az: give its unit, --accel-unit m/s^2|g|mg",
        ),
    ],
)
def test_bad_options(tmp_path: Path, args: list[str], fragment: str) -> None:
    assert fragment in import_error(tmp_path / "o.csv", logger_file(tmp_path), *args)


def test_bad_output_extension_is_refused_before_work(tmp_path: Path) -> None:
    assert "unsupported extension" in import_error(tmp_path / "o.tsv", logger_file(tmp_path), *BASIC)


def test_missing_foreign_file(tmp_path: Path) -> None:
    assert "no such file" in import_error(tmp_path / "o.csv", tmp_path / "absent.csv", *BASIC)


def test_cli_exit_code_and_one_line_message(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = [
        "import",
        str(logger_file(tmp_path)),
        "--time",
        "t",
        "--temp",
        "x",
        "--accel",
        "az",
        "--accel-unit",
        "mg",
        "-o",
        "o.csv",
    ]
    assert run_cli(main, argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ")
    assert err.count("\n") == 1


def test_another_preset_column_is_named_as_its_own_channel(tmp_path: Path, real_run: Path) -> None:
    """--accel imu.acc.x with the tofupilot preset is the x channel, not the preset's default z."""
    rec = run_import(real_run, "--preset", "tofupilot", "--accel", "imu.acc.x", "-o", tmp_path / "x.csv")
    assert rec.meta["channel"] == "accel0_x" and rec.meta["sensor"] == "tofupilot-imu-acc-x"
    np.testing.assert_array_equal(rec.accel_mg, rec.columns["accel_x_mg"])
