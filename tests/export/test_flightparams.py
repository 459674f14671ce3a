"""``codegen export --format px4-params|ardupilot-parm``: the written parameters, applied by independent
re-implementations of PX4's and ArduPilot's published formulas (float32, as the autopilots compute),
match the model's drift within 1e-6 of its range.

PX4, src/modules/temperature_compensation/TemperatureCompensation.cpp (calc_thermal_offsets_3D):
    dT = clamp(T, TMIN, TMAX) - TREF; offset = X0 + X1 dT + X2 dT^2 + X3 dT^3; corrected = raw - offset.
ArduPilot, libraries/AP_InertialSensor/AP_InertialSensor_tempcal.cpp (correct_sensor):
    P(d) = (C1 + (C2 + C3 d) d) d * 1e-6; corrected = raw - P(clamp(T) - 35) + P(clamp(CALTEMP) - 35).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from trainer.checkpoint import load_model
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import UserError

G = 9.80665  # m/s^2 per g
F32 = np.float32
DEVICE_ID = 2490378


def read_px4_params(path: Path) -> dict[str, float]:
    """QGroundControl's format: '#' comments, then 'vehicle component name value type' tab-separated."""
    values = {}
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            continue
        vehicle, component, name, value, kind = line.split("\t")
        assert (vehicle, component) == ("1", "1") and kind in ("6", "9")
        values[name] = float(value) if kind == "9" else int(value)
    return values


def read_ardupilot_parm(path: Path) -> dict[str, float]:
    values = {}
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            name, value = line.split(" ")
            values[name] = float(value)
    return values


def px4_offset(params: dict[str, float], prefix: str, axis: int, temp_c: np.ndarray) -> np.ndarray:
    """calc_thermal_offsets_3D in float32."""
    tmin, tmax, tref = (
        F32(params[f"{prefix}_TMIN"]),
        F32(params[f"{prefix}_TMAX"]),
        F32(params[f"{prefix}_TREF"]),
    )
    t = temp_c.astype(F32)
    dt = np.where(t > tmax, tmax - tref, np.where(t < tmin, tmin - tref, t - tref)).astype(F32)
    x0, x1, x2, x3 = (F32(params[f"{prefix}_X{k}_{axis}"]) for k in range(4))
    dt2 = dt * dt
    dt3 = dt2 * dt
    return (x0 + x1 * dt + x2 * dt2 + x3 * dt3).astype(F32)


def ardupilot_correction(
    params: dict[str, float], imu: int, sensor: str, axis: str, temp_c: np.ndarray, cal_temp_c: float
) -> np.ndarray:
    """What correct_sensor subtracts from the raw value, in float32."""
    prefix = f"INS_TCAL{imu + 1}"
    tmin, tmax = F32(params[f"{prefix}_TMIN"]), F32(params[f"{prefix}_TMAX"])
    c1, c2, c3 = (F32(params[f"{prefix}_{sensor}{k}_{axis}"]) for k in (1, 2, 3))

    def poly(d: np.ndarray) -> np.ndarray:
        return ((c1 + (c2 + c3 * d) * d) * d * F32(1.0e-6)).astype(F32)

    t = np.clip(temp_c.astype(F32), tmin, tmax)
    cal = np.clip(F32(cal_temp_c), tmin, tmax)
    return poly(t - F32(35.0)) - poly(np.array([cal - F32(35.0)], dtype=F32))


def chamber_recording(path: Path, *, axis_offset_mg: float, meta: dict[str, str], seed: int) -> Path:
    """A 1 Hz chamber run, -20 -> 60 -> -10 degC, with a cubic drift and noise."""
    rng = np.random.default_rng(seed)
    temp = np.concatenate([np.linspace(-20, 60, 900), np.linspace(60, -10, 700)])
    d = temp - 20.0
    drift = 5.0 + 0.3 * d - 0.004 * d**2 + 2e-5 * d**3 + rng.normal(0, 0.05, temp.size)
    rec = Recording(
        {"time_s": np.arange(temp.size, dtype=float), "temp_c": temp, "accel_mg": axis_offset_mg + drift},
        {"sample_rate_hz": "1", **meta},
    )
    write_recording(rec, path)
    return path


def fit(path: Path, out: Path, method: str = "poly3", *extra: str) -> Path:
    assert trainer_main(["fit", "--method", method, str(path), "-o", str(out), *extra]) == 0
    return out


def export(out_dir: Path, fmt: str, *args: str | Path) -> Path:
    assert codegen_main(["export", *map(str, args), "-o", str(out_dir), "--format", fmt]) == 0
    (written,) = out_dir.iterdir()
    return written


def model_drift(model_path: Path, temp_c: np.ndarray) -> tuple[np.ndarray, float]:
    """The model's drift at ``temp_c`` and its range over the training range (mg)."""
    model, _ = load_model(model_path)
    lo, hi = model.temp_range_c
    span = model.drift_at(np.linspace(lo, hi, 4001))
    return model.drift_at(temp_c), float(span.max() - span.min())


@pytest.fixture(scope="module")
def xyz_models(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """poly3 fitted on accel0_x, _y, _z of one device (z carries gravity)."""
    root = tmp_path_factory.mktemp("xyz")
    models = {}
    for seed, (axis, offset) in enumerate({"x": 12.0, "y": -7.0, "z": -1000.0}.items()):
        meta = {"channel": f"accel0_{axis}", "device_id_accel0": str(DEVICE_ID)}
        rec = chamber_recording(root / f"{axis}.csv", axis_offset_mg=offset, meta=meta, seed=seed)
        models[axis] = fit(rec, root / f"{axis}.pt")
    return models


def grid(model_path: Path) -> np.ndarray:
    model, _ = load_model(model_path)
    lo, hi = model.temp_range_c
    return np.concatenate([np.linspace(lo - 15, hi + 15, 3001), [lo, hi]])


def test_px4_params_match_the_model_drift(tmp_path: Path, xyz_models: dict[str, Path]) -> None:
    written = export(tmp_path / "px4", "px4-params", *xyz_models.values())
    assert written.name == "px4_thermal.params"
    params = read_px4_params(written)
    assert params["TC_A_ENABLE"] == 1 and params["TC_A0_ID"] == DEVICE_ID
    for index, axis in enumerate("xyz"):
        temp = grid(xyz_models[axis])
        drift, drift_range = model_drift(xyz_models[axis], temp)
        at_ref, _ = model_drift(xyz_models[axis], np.array([params["TC_A0_TREF"]]))
        offset_mg = px4_offset(params, "TC_A0", index, temp).astype(float) * 1000.0 / G
        # X0 = 0: the stack subtracts drift(T) - drift(TREF); its ordinary calibration owns the constant
        np.testing.assert_allclose(offset_mg, drift - at_ref[0], rtol=0, atol=1e-6 * drift_range)
        assert params[f"TC_A0_X0_{index}"] == 0.0


def test_px4_keep_constant_writes_x0_and_refuses_gravity(tmp_path: Path) -> None:
    # fitted with --offset absolute, the model holds its constant (12 mg + the drift at T_ref)
    meta = {"channel": "accel0_x", "device_id_accel0": str(DEVICE_ID)}
    rec = chamber_recording(tmp_path / "x.csv", axis_offset_mg=12.0, meta=meta, seed=0)
    absolute_x = fit(rec, tmp_path / "x_abs.pt", "poly3", "--offset", "absolute")
    written = export(tmp_path / "x", "px4-params", absolute_x, "--keep-constant")
    params = read_px4_params(written)
    temp = grid(absolute_x)
    drift, drift_range = model_drift(absolute_x, temp)
    offset_mg = px4_offset(params, "TC_A0", 0, temp).astype(float) * 1000.0 / G
    np.testing.assert_allclose(offset_mg, drift, rtol=0, atol=1e-6 * drift_range)
    assert params["TC_A0_X1_1"] == 0.0 and params["TC_A0_X3_2"] == 0.0  # y, z: no model given
    assert "axes y, z: no model given" in written.read_text()
    # The default fit leaves gravity to the accelerometer calibration (relative to T_ref); a model
    # fitted with its absolute constant holds it, and --keep-constant refuses to write it.
    meta = {"channel": "accel0_z", "device_id_accel0": str(DEVICE_ID)}
    rec = chamber_recording(tmp_path / "z.csv", axis_offset_mg=-1000.0, meta=meta, seed=2)
    absolute = fit(rec, tmp_path / "z_abs.pt", "poly3", "--offset", "absolute-unbounded")
    with pytest.raises(UserError, match="holds gravity"):
        codegen_main(
            [
                "export",
                str(absolute),
                "-o",
                str(tmp_path / "z"),
                "--format",
                "px4-params",
                "--keep-constant",
            ]
        )
    assert not (tmp_path / "z").exists()


def test_px4_keep_constant_refuses_a_model_fitted_relative_to_t_ref(
    tmp_path: Path, xyz_models: dict[str, Path]
) -> None:
    # The default fit (--offset relative) moved the constant out of the model: X0 would be 0 whatever
    # --keep-constant says. x: 12 mg + the drift's 5 mg at T_ref = 20 degC (the run's mid-point), which
    # --offset absolute keeps; z: gravity, which it refuses (above 100 mg).
    for axis, constant_mg, hint in (
        ("x", 17.0, "refit with 'trainer fit --offset absolute'"),
        ("z", -995.0, "imported with --remove-gravity"),
    ):
        message = refused(tmp_path, xyz_models[axis], "--format", "px4-params", "--keep-constant")
        assert message.startswith(f"accel0_{axis}: --keep-constant: the model holds no constant to keep")
        assert "--offset relative" in message and hint in message
        stated = re.search(r"its constant, (\S+) mg at T_ref 20.00 degC", message)
        assert stated is not None and float(stated.group(1)) == pytest.approx(constant_mg, abs=0.1)


def test_ardupilot_parm_matches_the_model_drift(tmp_path: Path, xyz_models: dict[str, Path]) -> None:
    written = export(tmp_path / "ap", "ardupilot-parm", *xyz_models.values())
    assert written.name == "ardupilot_tcal.parm"
    params = read_ardupilot_parm(written)
    assert params["INS_TCAL1_ENABLE"] == 1
    assert params["INS_TCAL1_GYR2_Y"] == 0.0  # no gyroscope model given
    for axis in "xyz":
        temp = grid(xyz_models[axis])
        for cal_temp in (20.0, 35.0, 55.5):  # INS_ACC1_CALTEMP: the temperature of the ordinary calibration
            drift, drift_range = model_drift(xyz_models[axis], temp)
            at_cal, _ = model_drift(xyz_models[axis], np.array([cal_temp]))
            subtracted = ardupilot_correction(params, 0, "ACC", axis.upper(), temp, cal_temp).astype(float)
            np.testing.assert_allclose(
                subtracted * 1000.0 / G, drift - at_cal[0], rtol=0, atol=1e-6 * drift_range
            )


def test_parm_comment_names_the_axes_written_as_zero(tmp_path: Path, xyz_models: dict[str, Path]) -> None:
    # a z-only accelerometer: x and y are written as zero and the file says so, as the .params does
    written = export(tmp_path / "z", "ardupilot-parm", xyz_models["z"])
    params = read_ardupilot_parm(written)
    assert all(params[f"INS_TCAL1_ACC{k}_{axis}"] == 0.0 for k in (1, 2, 3) for axis in "XY")
    assert params["INS_TCAL1_ACC1_Z"] != 0.0
    comments = [line for line in written.read_text().splitlines() if "no model given" in line]
    assert comments == [
        "# accel0 axes x, y: no model given, coefficients 0",
        "# gyro0: no model given, coefficients 0",
    ]
    every_axis = export(tmp_path / "xyz", "ardupilot-parm", *xyz_models.values()).read_text()
    assert "accel0 axes" not in every_axis and "# gyro0: no model given" in every_axis


def test_gyro_channel_is_converted_to_rad_per_s(tmp_path: Path) -> None:
    # a model of a gyroscope axis: its unit is deg/s, the stacks' rad/s
    meta = {"channel": "gyro1_y", "unit": "dps"}
    gyro = fit(
        chamber_recording(tmp_path / "g.csv", axis_offset_mg=0.5, meta=meta, seed=4), tmp_path / "g.pt"
    )
    written = export(tmp_path / "g", "px4-params", gyro, "--device-id", "77")
    params = read_px4_params(written)
    assert params["TC_G_ENABLE"] == 1 and params["TC_G1_ID"] == 77 and "TC_A_ENABLE" not in params
    temp = grid(gyro)
    drift, drift_range = model_drift(gyro, temp)
    at_ref, _ = model_drift(gyro, np.array([params["TC_G1_TREF"]]))
    offset_dps = np.degrees(px4_offset(params, "TC_G1", 1, temp).astype(float))
    np.testing.assert_allclose(offset_dps, drift - at_ref[0], rtol=0, atol=1e-6 * drift_range)


def test_export_is_deterministic_and_refuses_what_a_stack_cannot_hold(
    tmp_path: Path, xyz_models: dict[str, Path]
) -> None:
    first = export(tmp_path / "a", "px4-params", *xyz_models.values()).read_bytes()
    assert export(tmp_path / "b", "px4-params", *xyz_models.values()).read_bytes() == first
    rec = chamber_recording(tmp_path / "r.csv", axis_offset_mg=0.0, meta={}, seed=9)
    pla = fit(rec, tmp_path / "pla.pt", "pla")
    baro_meta = {"channel": "baro0", "unit": "pa"}
    baro = fit(
        chamber_recording(tmp_path / "b.csv", axis_offset_mg=101325.0, meta=baro_meta, seed=5),
        tmp_path / "b.pt",
    )
    messages = []
    for args in (
        [pla],  # ten lines are not one cubic
        [fit(rec, tmp_path / "nochan.pt")],  # no channel recorded
        [tmp_path / "nochan.pt", "--channel", "accel0_x"],  # PX4 needs the device id
        [baro, "--format", "ardupilot-parm"],  # INS_TCAL: IMUs only
        [xyz_models["x"], "--channel", "accel3_x", "--format", "ardupilot-parm"],  # INS_TCAL1..3
    ):
        argv = ["export", *map(str, args), "-o", str(tmp_path / "out")]
        if "--format" not in argv:
            argv += ["--format", "px4-params"]
        with pytest.raises(UserError) as caught:
            codegen_main(argv)
        messages.append(str(caught.value))
        assert "\n" not in messages[-1] and not (tmp_path / "out").exists()
    assert "method 'pla' is not a cubic of the temperature" in messages[0]
    assert "pass --channel" in messages[1]
    assert "pass --device-id" in messages[2]
    assert "accelerometers and gyroscopes only" in messages[3]
    assert "INS_TCAL1..3" in messages[4]


def test_a_one_interval_pla_is_a_line(tmp_path: Path) -> None:
    rec = chamber_recording(tmp_path / "r.csv", axis_offset_mg=3.0, meta={"channel": "accel2_x"}, seed=4)
    model_path = fit(rec, tmp_path / "pla1.pt", "pla", "--intervals", "1")
    params = read_ardupilot_parm(export(tmp_path / "ap", "ardupilot-parm", model_path))
    model, _ = load_model(model_path)
    lo, hi = model.temp_range_c
    temp = np.linspace(lo, hi, 1001)  # inside the range (PLA extrapolates, the stacks clamp)
    drift = model.drift_at(temp)
    expected = drift - model.drift_at(np.array([25.0]))[0]
    subtracted = ardupilot_correction(params, 2, "ACC", "X", temp, 25.0).astype(float) * 1000.0 / G
    np.testing.assert_allclose(subtracted, expected, rtol=0, atol=1e-6 * float(np.ptp(drift)))
    assert params["INS_TCAL3_ACC2_X"] == 0.0 and params["INS_TCAL3_ACC3_X"] == 0.0


def test_real_run_parameters_match_the_model(tmp_path: Path, real_run: Path) -> None:
    rec = tmp_path / "real.npz"
    assert trainer_main(["import", str(real_run), "--preset", "tofupilot", "-o", str(rec)]) == 0
    model_path = fit(rec, tmp_path / "poly3.pt")
    px4 = read_px4_params(export(tmp_path / "px4", "px4-params", model_path, "--device-id", str(DEVICE_ID)))
    ap = read_ardupilot_parm(export(tmp_path / "ap", "ardupilot-parm", model_path))
    temp = grid(model_path)
    drift, drift_range = model_drift(model_path, temp)
    at_ref, _ = model_drift(model_path, np.array([px4["TC_A0_TREF"]]))
    np.testing.assert_allclose(
        px4_offset(px4, "TC_A0", 2, temp).astype(float) * 1000.0 / G,
        drift - at_ref[0],
        atol=1e-6 * drift_range,
    )
    at_cal, _ = model_drift(model_path, np.array([25.0]))
    subtracted = ardupilot_correction(ap, 0, "ACC", "Z", temp, 25.0).astype(float) * 1000.0 / G
    np.testing.assert_allclose(subtracted, drift - at_cal[0], atol=1e-6 * drift_range)


def ramp_recording(path: Path, temp_c: np.ndarray, drift_mg: np.ndarray, meta: dict[str, str]) -> Path:
    """A noise-free 1 Hz recording: ``drift_mg`` at ``temp_c``, so poly3 recovers a cubic drift exactly."""
    rec = Recording(
        {"time_s": np.arange(temp_c.size, dtype=float), "temp_c": temp_c, "accel_mg": drift_mg},
        {"sample_rate_hz": "1", **meta},
    )
    write_recording(rec, path)
    return path


def refused(tmp_path: Path, *args: str | Path) -> str:
    """The one-line error of a refused export; nothing written."""
    out = tmp_path / "refused"
    with pytest.raises(UserError) as caught:
        codegen_main(["export", *map(str, args), "-o", str(out)])
    message = str(caught.value)
    assert "\n" not in message and not out.exists()
    return message


ACCEL_Z = {"channel": "accel0_z", "device_id_accel0": str(DEVICE_ID)}


def test_a_cubic_fitted_to_noise_is_refused_whatever_the_fit_accepted(tmp_path: Path) -> None:
    # the log: 6 samples over 0.34 degC; trainer fit refuses it and says what to record instead
    rng = np.random.default_rng(3)
    temp = np.array([25.0, 25.07, 25.13, 25.2, 25.27, 25.34])
    tiny = ramp_recording(tmp_path / "tiny.csv", temp, -1000.0 + rng.normal(0, 1, 6), ACCEL_Z)
    with pytest.raises(UserError) as caught:
        fit(tiny, tmp_path / "no.pt")
    assert "spans 0.34 degC" in str(caught.value) and "SDLOG_PROFILE bit 2" in str(caught.value)
    assert "INS_TCALn_ENABLE=2" in str(caught.value)
    # accepted at fit, the cubic through noise moves by metres per s^2 within the 10 degC a cubic needs
    model = fit(tiny, tmp_path / "tiny.pt", "poly3", "--accept-implausible")
    cubic = np.polynomial.Polynomial(load_model(model)[0].coefficients)  # mg, in T - T_ref
    t_ref = load_model(model)[0].t_ref_c
    wide = np.linspace(25.17 - 5.0, 25.17 + 5.0, 20001) - t_ref
    assert np.ptp(cubic(wide)) * G / 1000.0 > 2.0  # the premise: beyond any accelerometer's drift
    for fmt in ("px4-params", "ardupilot-parm"):
        message = refused(tmp_path, model, "--format", fmt)
        assert (
            message.startswith("accel0_z: the cubic's correction moves by") and "fitted to noise" in message
        )
        assert "widened to 10 degC" in message and "SDLOG_PROFILE" in message


def test_the_physical_bound_is_two_metres_per_second_squared(tmp_path: Path) -> None:
    # noise-free linear drifts over 0..80 degC, fitted without --accept-implausible: 180 mg passes,
    # 230 mg (2.26 m/s^2) is refused in both formats; as a gyroscope (deg/s) both exceed 0.5 rad/s
    temp = np.linspace(0.0, 80.0, 801)
    models = {}
    for total_mg in (180.0, 230.0):
        rec = ramp_recording(tmp_path / f"r{total_mg:g}.csv", temp, total_mg * temp / 80.0, ACCEL_Z)
        models[total_mg] = fit(rec, tmp_path / f"m{total_mg:g}.pt")
    for fmt in ("px4-params", "ardupilot-parm"):
        export(tmp_path / f"ok-{fmt}", fmt, models[180.0])
        message = refused(tmp_path, models[230.0], "--format", fmt)
        assert "moves by 2.26 m/s^2 over 0.00 .. 80.00 degC" in message and "(2 m/s^2)" in message
    gyro_meta = {"channel": "gyro0_z", "unit": "dps"}
    gyro = fit(ramp_recording(tmp_path / "g.csv", temp, 180.0 * temp / 80.0, gyro_meta), tmp_path / "g.pt")
    message = refused(tmp_path, gyro, "--device-id", "7", "--format", "px4-params")
    assert f"moves by {np.radians(180.0):.3g} rad/s" in message and "a gyroscope's offset" in message


def test_device_id_0_is_refused(tmp_path: Path, xyz_models: dict[str, Path]) -> None:
    # PX4 applies TC_A0_* to the sensor whose device id equals TC_A0_ID: 0 matches none
    for args in (
        [xyz_models["x"], "--device-id", "0"],
        [*xyz_models.values(), "--device-id", "accel0=0"],
        [xyz_models["x"], "--device-id", str(2**31)],  # beyond PX4's int32 parameter
    ):
        message = refused(tmp_path, *args, "--format", "px4-params")
        assert message.startswith("accel0: device id ") and "nothing would be compensated" in message
    meta = {"channel": "accel0_x", "device_id_accel0": "0"}  # as recorded by an import
    rec = chamber_recording(tmp_path / "r.csv", axis_offset_mg=0.0, meta=meta, seed=5)
    assert "device id 0 names no sensor" in refused(
        tmp_path, fit(rec, tmp_path / "m.pt"), "--format", "px4-params"
    )


def test_parm_header_says_enable_hides_the_rest(tmp_path: Path, xyz_models: dict[str, Path]) -> None:
    lines = export(tmp_path / "ap", "ardupilot-parm", xyz_models["x"]).read_text().splitlines()
    first_parameter = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    header = " ".join(line.lstrip("# ") for line in lines[:first_parameter])
    assert "hides INS_TCALn_* while INS_TCALn_ENABLE is 0" in header
    assert "load this file again" in header and "redo the accelerometer calibration" in header


def test_px4_republish_rule_on_a_staircase() -> None:
    from codegen.px4_republish import republish_error, republished_temperature

    # up in 0.5 degC steps, then down: a new offset only once the temperature is more than 1 degC
    # from the last published one (exactly 1 degC is not enough), in either direction
    temp = np.array([20.0, 20.0, 20.5, 21.0, 21.5, 21.5, 22.0, 22.5, 23.0, 22.5, 22.0, 21.5, 21.0])
    applied = [20.0, 20.0, 20.0, 20.0, 21.5, 21.5, 21.5, 21.5, 23.0, 23.0, 23.0, 21.5, 21.5]
    np.testing.assert_array_equal(republished_temperature(temp), applied)
    # a slow ramp of 0.25 degC per sample: published every 1.25 degC (5 samples), from the first
    ramp = 20.0 + 0.25 * np.arange(40)
    np.testing.assert_array_equal(republished_temperature(ramp), 20.0 + 1.25 * (np.arange(40) // 5))
    # the error of a linear drift is its slope times the lag
    error = republish_error(lambda t: 3.0 * t, ramp)
    np.testing.assert_allclose(error, 3.0 * (republished_temperature(ramp) - ramp))


def test_px4_export_prints_the_republish_bound(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from codegen.px4_republish import lag_bound

    # a linear drift of 0.8 mg/degC: a 1 degC-old offset is off by up to 0.8 mg
    temp = np.linspace(0.0, 40.0, 401)
    linear = fit(ramp_recording(tmp_path / "l.csv", temp, 0.8 * temp, ACCEL_Z), tmp_path / "l.pt")
    capsys.readouterr()
    export(tmp_path / "px4", "px4-params", linear)
    said = capsys.readouterr().out
    assert (
        "accel0_z: PX4 updates the applied offset after > 1 degC of change, checked at 1 Hz: up to 0.8 mg"
        in said
    )
    # between two 1 Hz checks a 10 degC/min ramp moves 1/6 degC more: 0.8 x (1 + 1/6) = 0.933 mg
    assert "0.933 mg while the temperature moves 10 degC/min" in said
    # a cubic: the bound is its steepest slope over the range (numerical derivative on a dense grid)
    from codegen.flightparams import load_channel_cubic

    cubic_model = fit(
        chamber_recording(tmp_path / "c.csv", axis_offset_mg=0.0, meta=ACCEL_Z, seed=6), tmp_path / "c.pt"
    )
    model, _ = load_model(cubic_model)
    lo, hi = model.temp_range_c
    dense = np.linspace(lo, hi, 200001)
    steepest = float(np.max(np.abs(np.gradient(model.drift_at(dense), dense))))
    cubic = load_channel_cubic(cubic_model)
    assert lag_bound(cubic, lo, hi) == pytest.approx(steepest, rel=1e-4)


@pytest.mark.parametrize("orientation", [0, 2])
def test_ardupilot_parm_of_a_log_in_vehicle_axes_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], orientation: int
) -> None:
    """ArduPilot logs IMU values after the board rotation (AHRS_ORIENTATION) but applies INS_TCAL before
    it: a model fitted on a rotated board's log would put its coefficients on the wrong axes, so the
    .parm export refuses it in one line and writes nothing; an unrotated board's log exports."""
    from tests.flightlogs import DataFlashWriter

    writer = DataFlashWriter()
    writer.parm(1000, "AHRS_ORIENTATION", float(orientation))
    temp_c = np.linspace(10.0, 50.0, 400)
    for row, t in enumerate(temp_c):
        small = 1e-4 * (t - 30.0)  # every axis varies: a constant output is refused as no sensor's
        accel = np.array([0.01 * (t - 30.0), small, -G + 1e-4 * (t - 30.0) ** 2])
        writer.imu(1_000_000 + 500_000 * row, 0, np.array([0.001 * (t - 30.0), small, small]), accel, t)
    log = writer.write(tmp_path / "rotated.bin")
    recording, fitted = tmp_path / "rec.npz", tmp_path / "fit"
    assert trainer_main(["import", str(log), "--channels", "all", "-o", str(recording)]) == 0
    said = capsys.readouterr().out
    assert (f"AHRS_ORIENTATION={orientation}" in said) == bool(orientation)
    assert (
        trainer_main(["fit", "--method", "poly3", "--channels", "all", str(recording), "-o", str(fitted)])
        == 0
    )
    stats = load_model(fitted / "accel0_x.pt")[1]["train_stats"]
    assert stats.get("ahrs_orientation") == (orientation or None)
    parm = tmp_path / "parm"
    argv = ["export", str(fitted), "--channels", "all", "--format"]
    if orientation:
        with pytest.raises(
            UserError, match=r"AHRS_ORIENTATION=2, whose IMU axes are the vehicle's.*sensor frame"
        ):
            codegen_main([*argv, "ardupilot-parm", "-o", str(parm)])
        assert not parm.exists()
    else:
        assert codegen_main([*argv, "ardupilot-parm", "-o", str(parm)]) == 0
        values = read_ardupilot_parm(next(parm.glob("*.parm")))
        # the x axis' drift 0.01 m/s^2 per degC about 30 degC, re-expanded about 35 degC (x 1e6)
        assert values["INS_TCAL1_ACC1_X"] == pytest.approx(1e4, rel=1e-3)


def test_a_channel_of_another_unit_than_the_model_s_is_refused(
    tmp_path: Path, xyz_models: dict[str, Path]
) -> None:
    """--channel renames the axis a model is written for; naming a gyroscope for an accelerometer
    model (mg) would write milli-g as rad/s, so it is refused in one line and nothing is written."""
    out = tmp_path / "params"
    argv = [
        "export",
        str(xyz_models["x"]),
        "--format",
        "px4-params",
        "--device-id",
        str(DEVICE_ID),
        "-o",
        str(out),
    ]
    with pytest.raises(
        UserError, match=r"--channel gyro0_x is in deg/s, but the model was fitted on a channel in mg"
    ):
        codegen_main([*argv, "--channel", "gyro0_x"])
    assert not out.exists()
    assert codegen_main([*argv, "--channel", "accel1_x"]) == 0
