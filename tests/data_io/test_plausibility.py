"""Plausibility checks with hints in ``trainer import`` and ``trainer fit``, and clean error text."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from trainer.cli import main
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording
from trainer.errors import UserError, run_cli

G = 9.80665


def write_text(path: Path, header: str, rows: list[str]) -> Path:
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


def logger_file(path: Path, *, step: float = 0.01, accel: float = -1000.0, temp0: float = 20.0) -> Path:
    """t, T, a: 40 rows, temperature rising 0.5 degC per row."""
    rows = [f"{k * step:.6f},{temp0 + 0.5 * k:.3f},{accel + 0.001 * k:.4f}" for k in range(40)]
    return write_text(path, "t,T,a", rows)


def cli_error(*args: str | Path) -> str:
    argv = [str(a) for a in args]
    with pytest.raises(UserError) as caught:
        main(argv)
    message = str(caught.value)
    assert "\n" not in message and "\x1b" not in message
    if "-o" in argv:
        assert not Path(argv[argv.index("-o") + 1]).exists()
    return message


IMPORT = ("--time", "t", "--temp", "T", "--accel", "a", "--accel-unit", "mg")


# --------------------------------------------------------------------------- import


def test_mps2_declared_as_g_is_refused_with_a_hint(tmp_path: Path) -> None:
    src = logger_file(tmp_path / "log.csv", accel=-9.81)
    message = cli_error("import", src, *IMPORT, "--accel-unit", "g", "-o", tmp_path / "o.csv")
    assert "column 'a'" in message and "m/s^2?" in message and "--accel-unit m/s^2" in message
    # the right unit imports; --accept-implausible keeps the user's word with a warning
    assert main(["import", str(src), *IMPORT, "--accel-unit", "m/s^2", "-o", str(tmp_path / "ok.csv")]) == 0
    assert read_recording(tmp_path / "ok.csv").accel_mg[0] == pytest.approx(-9.81 / G * 1000)
    out = tmp_path / "g.csv"
    assert (
        main(["import", str(src), *IMPORT, "--accel-unit", "g", "--accept-implausible", "-o", str(out)]) == 0
    )
    assert read_recording(out).accel_mg[0] == pytest.approx(-9810.0)


@pytest.mark.parametrize("time_base", [[], ["--retime"], ["--resample", "50"]])
@pytest.mark.parametrize(("step", "declared", "right"), [(20.0, "s", "ms"), (20_000.0, "ms", "us")])
def test_a_time_column_in_another_unit_is_refused_naming_the_likely_one(
    tmp_path: Path, step: float, declared: str, right: str, time_base: list[str]
) -> None:
    """A 50 Hz logger's ms column declared as s, or its us column declared as ms: the hint names the
    unit that gives a rate IMU logs are written at (it said "milliseconds read as seconds?" to both,
    and with --retime or --resample still did)."""
    src = logger_file(tmp_path / "log.csv", step=step)
    message = cli_error("import", src, *IMPORT, "--time-unit", declared, *time_base, "-o", tmp_path / "o.csv")
    assert "0.05 Hz is below 0.1 Hz" in message and f"--time-unit {right} gives 50 Hz" in message
    assert message.count("--time-unit") == 1  # the other units give no plausible rate
    rec_path = tmp_path / "ok.csv"
    assert main(["import", str(src), *IMPORT, "--time-unit", right, "-o", str(rec_path)]) == 0
    assert float(read_recording(rec_path).meta["sample_rate_hz"]) == pytest.approx(50.0)


def test_a_rate_above_100_khz_is_refused(tmp_path: Path) -> None:
    src = logger_file(tmp_path / "log.csv", step=5.0)  # 5 ms steps...
    message = cli_error(
        "import", src, *IMPORT, "--time-unit", "us", "-o", tmp_path / "o.csv"
    )  # ...read as us
    assert "200 kHz" not in message and "above 100 kHz" in message and "--time-unit" in message


def test_kelvin_is_refused_and_temp_unit_k_converts(tmp_path: Path) -> None:
    src = logger_file(tmp_path / "log.csv", temp0=293.15)
    message = cli_error("import", src, *IMPORT, "-o", tmp_path / "o.csv")
    assert "above 150 degC" in message and "kelvin?" in message and "--temp-unit K" in message
    assert main(["import", str(src), *IMPORT, "--temp-unit", "K", "-o", str(tmp_path / "ok.csv")]) == 0
    np.testing.assert_allclose(read_recording(tmp_path / "ok.csv").temp_c[:3], [20.0, 20.5, 21.0], atol=1e-9)


def test_decimal_comma_hint_and_option(tmp_path: Path) -> None:
    rows = [f"{k * 0.01:.2f};{20 + 0.5 * k:.2f};{-1000 + 0.25 * k:.2f}".replace(".", ",") for k in range(10)]
    src = write_text(tmp_path / "de.csv", "t;T;a", rows)
    message = cli_error("import", src, *IMPORT, "-o", tmp_path / "o.csv")
    assert (
        "line 2, column 't'" in message
        and "'0,00' is not a number" in message
        and "--decimal-comma" in message
    )
    out = tmp_path / "ok.csv"
    assert main(["import", str(src), *IMPORT, "--decimal-comma", "-o", str(out)]) == 0
    rec = read_recording(out)
    np.testing.assert_allclose(rec.accel_mg, -1000 + 0.25 * np.arange(10))
    np.testing.assert_allclose(rec.temp_c, 20 + 0.5 * np.arange(10))
    message = cli_error(
        "import", src, *IMPORT, "--decimal-comma", "--delimiter", "comma", "-o", tmp_path / "x.csv"
    )
    assert "--decimal-comma needs a tab or semicolon delimiter" in message
    # a file split by commas, --decimal-comma without --delimiter: the cause, not "pass --delimiter"
    points = write_text(tmp_path / "en.csv", "t,T,a", [r.replace(",", ".").replace(";", ",") for r in rows])
    message = cli_error("import", points, *IMPORT, "--decimal-comma", "-o", tmp_path / "y.csv")
    assert "split alike by commas only" in message and "a comma cannot be both" in message
    assert "drop --decimal-comma" in message


def test_slow_temperature_channel_hint_and_fill_previous(tmp_path: Path) -> None:
    # the temperature is logged on every third row only, starting on the second
    rows = [
        f"{k * 0.01:.2f},{20 + k / 10:.1f},{-1000 + k}" if k % 3 == 1 else f"{k * 0.01:.2f},,{-1000 + k}"
        for k in range(12)
    ]
    src = write_text(tmp_path / "slow.csv", "t,T,a", rows)
    message = cli_error("import", src, *IMPORT, "-o", tmp_path / "o.csv")
    assert "line 2, column 'T': empty field" in message and "--fill-temp previous" in message
    out = tmp_path / "ok.csv"
    assert main(["import", str(src), *IMPORT, "--fill-temp", "previous", "-o", str(out)]) == 0
    rec = read_recording(out)
    expected_temp = [
        20 + (1 + 3 * ((k - 1) // 3)) / 10 for k in range(1, 12)
    ]  # the last reading at or before k
    np.testing.assert_allclose(rec.temp_c, expected_temp)
    np.testing.assert_allclose(
        rec.accel_mg, -1000 + np.arange(1, 12)
    )  # the leading row without a reading is dropped
    assert "1 rows before the first reading dropped" in rec.meta["temp_filled"]


# --------------------------------------------------------------------------- fit


def recording(path: Path, *, temp: np.ndarray, accel: np.ndarray, rate_hz: float = 10.0) -> Path:
    n = len(temp)
    rec = Recording(
        {"time_s": np.arange(n) / rate_hz, "temp_c": temp, "accel_mg": accel},
        {"sample_rate_hz": f"{rate_hz:g}"},
    )
    write_recording(rec, path)
    return path


def test_fit_refuses_an_accelerometer_in_g_read_as_mg(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A chamber run's z axis logged in g (-1 g and 25 mg of drift over 60 degC, 0.5 mg of noise) read
    as mg moves by 0.03 "mg": fitted, it gave a 0.0045 mg residual and a correction 1000x too small."""
    n = 2000
    temp = np.linspace(-20.0, 40.0, n)
    in_mg = -1000.0 + 25.0 * ((temp - 10.0) / 30.0) ** 2 + np.random.default_rng(1).normal(0.0, 0.5, n)
    as_g = recording(tmp_path / "g.csv", temp=temp, accel=in_mg / 1000.0)
    message = cli_error("fit", "--method", "poly3", as_g, "-o", tmp_path / "m.pt")
    moved = float(np.ptp(in_mg / 1000.0))
    assert f"moves by only {moved:.3g} mg over a 60 degC run" in message and "--accel-unit g" in message
    # the same run in mg, and one axis of a quiet sensor that moves by 0.2 mg, fit
    assert main(["fit", "--method", "poly3", str(recording(tmp_path / "mg.csv", temp=temp, accel=in_mg)),
                 "-o", str(tmp_path / "mg.pt")]) == 0  # fmt: skip
    quiet = recording(tmp_path / "q.csv", temp=temp, accel=0.2 * np.sin(np.linspace(0.0, 3.0, n)))
    assert main(["fit", "--method", "poly3", str(quiet), "-o", str(tmp_path / "q.pt")]) == 0
    capsys.readouterr()
    argv = ["fit", "--method", "poly3", str(as_g), "--accept-implausible", "-o", str(tmp_path / "g.pt")]
    assert main(argv) == 0 and "warning:" in capsys.readouterr().err  # the user's word, with a warning


@pytest.mark.parametrize("command", ["diagnose", "compare"])
def test_the_scoring_commands_refuse_an_accelerometer_in_g_read_as_mg_as_fit_does(
    tmp_path: Path, command: str
) -> None:
    """diagnose scored g read as mg and named a bias polynomial 1000x too small; compare ranked
    compensators on it. Both refuse it as fit does, with the same cause, and write nothing."""
    n = 2000
    temp = np.linspace(-20.0, 40.0, n)
    in_g = (-1000.0 + 25.0 * ((temp - 10.0) / 30.0) ** 2) / 1000.0
    as_g = recording(tmp_path / "g.csv", temp=temp, accel=in_g)
    out = tmp_path / "out"
    argv = (
        ("diagnose", as_g, "--report", out) if command == "diagnose" else ("compare", as_g, "--out-dir", out)
    )
    message = cli_error(*argv)
    assert f"moves by only {float(np.ptp(in_g)):.3g} mg over a 60 degC run" in message
    assert "--accel-unit g" in message and "trainer fit refuses it too" in message
    assert not out.exists()


def test_fit_refuses_a_span_too_small_for_the_cubic(tmp_path: Path) -> None:
    n = 400
    path = recording(tmp_path / "flat.csv", temp=25.0 + np.linspace(0, 0.12, n), accel=np.linspace(0, 1, n))
    message = cli_error("fit", "--method", "poly3", path, "-o", tmp_path / "m.pt")
    assert "spans 0.12 degC" in message and "too small for poly3 (needs 10 degC)" in message
    assert (
        main(["fit", "--method", "poly3", str(path), "-o", str(tmp_path / "m.pt"), "--accept-implausible"])
        == 0
    )


@pytest.mark.parametrize("method", ["physics", "dlstm-temp"])
def test_every_method_of_the_temperature_needs_its_span(tmp_path: Path, method: str) -> None:
    """physics (the cubic's backbone) and the temperature-input DLSTM fitted a 0.17 degC run and the
    physics model left 8.5 times what no compensation leaves on it; they refuse as poly3 does, and
    compare leaves them out with the reason (nothing written when none is left)."""
    n = 400
    path = recording(tmp_path / "flat.csv", temp=25.0 + np.linspace(0, 0.17, n), accel=np.linspace(0, 1, n))
    message = cli_error("fit", "--method", method, path, "-o", tmp_path / "m.pt")
    assert f"too small for {method} (needs 10 degC)" in message
    assert not (tmp_path / "m.pt").exists()
    out = tmp_path / "cv"
    message = cli_error("compare", path, "--methods", f"poly3,{method}", "--out-dir", out)
    assert f"too small for poly3, {method}" in message and not out.exists()


def test_the_span_refusal_names_the_channels_own_temperature_column(tmp_path: Path) -> None:
    """A gyroscope read against its own thermometer (``gyro0_temp_c``) that is stuck: the refusal
    names that column, not ``temp_c``, and comes before the accelerometer is fitted."""
    n = 400
    temp = np.linspace(-20.0, 60.0, n)
    rec = Recording(
        {
            "time_s": np.arange(n) / 10.0,
            "temp_c": temp,
            "accel0_x_mg": 0.01 * temp**2,
            "gyro0_x_dps": np.sin(np.arange(n)),
            "gyro0_temp_c": np.full(n, 25.0),
        },
        {"sample_rate_hz": "10"},
    )
    path = tmp_path / "stuck.csv"
    write_recording(rec, path)
    out = tmp_path / "models"
    message = cli_error("fit", "--method", "poly3", path, "--channels", "all", "-o", out)
    assert "column 'gyro0_temp_c'" in message and "[gyro0_x]" in message
    assert not out.exists()


def test_fit_refuses_gravity_in_g_and_kelvin_and_slow_rates(tmp_path: Path) -> None:
    n = 400
    temp = np.linspace(-20, 60, n)
    as_g = recording(tmp_path / "g.csv", temp=temp, accel=np.full(n, -9806.65) + temp)
    assert "m/s^2 declared as g at import?" in cli_error(
        "fit", "--method", "poly3", as_g, "-o", tmp_path / "m.pt"
    )
    kelvin = recording(tmp_path / "k.csv", temp=temp + 273.15, accel=temp)
    assert "kelvin?" in cli_error("fit", "--method", "poly3", kelvin, "-o", tmp_path / "m.pt")
    slow = recording(tmp_path / "s.csv", temp=temp, accel=temp, rate_hz=0.02)
    assert "milliseconds read as seconds?" in cli_error(
        "fit", "--method", "poly3", slow, "-o", tmp_path / "m.pt"
    )


# --------------------------------------------------------------------------- error text


def test_unsafe_model_error_gives_no_unsafe_advice_and_no_colour(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    path = tmp_path / "model.pt"
    torch.save({"format": "mems-tdc-model", "payload": Path("x")}, path)  # a pickled Python object
    rec = recording(tmp_path / "r.csv", temp=np.linspace(0, 40, 50), accel=np.zeros(50))
    assert run_cli(main, ["evaluate", str(path), str(rec)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1
    assert "refused to load" in err and "Path" in err
    assert "weights_only=False" not in err and "trust" not in err and "\x1b" not in err


def test_run_cli_strips_terminal_codes(capsys: pytest.CaptureFixture) -> None:
    def failing(argv: list[str] | None) -> int:
        raise UserError("x.csv: \x1b[1mbold\x1b[0m and \x1b[31mred\x1b[0m\nsecond line")

    assert run_cli(failing, []) == 2
    assert capsys.readouterr().err == "error: x.csv: bold and red second line\n"
