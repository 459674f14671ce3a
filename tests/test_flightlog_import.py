"""``trainer import`` of PX4 ULog and ArduPilot DataFlash logs written by the tests (tests/flightlogs.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.flightlogs import DataFlashWriter, baro_topic, imu_topic, write_ulog
from trainer.cli import main
from trainer.data.flightlog_io import read_flight_log
from trainer.data.importer import ImportOptions, import_foreign
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording
from trainer.errors import UserError, run_cli

G = 9.80665
N = 60
RATE_HZ = 50.0
RNG = np.random.default_rng(13)

# Per instance: device id, temperature ramp (degC), accel offsets (m/s^2), gyro offsets (rad/s).
ACCEL_IDS = {0: 2490378, 1: 3014666}
GYRO_IDS = {0: 2490634, 1: 3014922}
BARO_IDS = {0: 6620434}


def _time_us(offset_us: int = 0) -> np.ndarray:
    return (5_000_000 + offset_us + np.arange(N) * 1e6 / RATE_HZ).astype(np.int64)


def _ramp(instance: int) -> np.ndarray:
    """A temperature ramp with steps of 0.25 degC: exact in float32 and after adding 0.5."""
    return 20.0 + 3.0 * instance + 0.25 * np.arange(N)


def _accel(instance: int) -> np.ndarray:
    values = np.column_stack(
        [0.01 * instance + 0.001 * np.arange(N), 0.02 * np.ones(N), -G + 0.0005 * RNG.normal(size=N)]
    )
    return values.astype(np.float32).astype(np.float64)  # as logged: float32


def _gyro(instance: int) -> np.ndarray:
    return (
        (0.001 * (instance + 1) * np.ones((N, 3)) + 1e-4 * np.arange(N)[:, None])
        .astype(np.float32)
        .astype(np.float64)
    )


@pytest.fixture(scope="module")
def ulog_data() -> dict[str, np.ndarray]:
    data: dict[str, np.ndarray] = {}
    for i in (0, 1):
        data[f"accel{i}"], data[f"accel{i}_temp"] = _accel(i), _ramp(i)
        data[f"gyro{i}"], data[f"gyro{i}_temp"] = _gyro(i), _ramp(i) + 0.5  # exact in float32 too
    data["baro0"] = np.linspace(101325.0, 101300.0, N // 5).astype(np.float32).astype(np.float64)
    data["baro0_temp"] = np.linspace(25.0, 38.0, N // 5).astype(np.float32).astype(np.float64)
    return data


@pytest.fixture(scope="module")
def ulog_path(tmp_path_factory: pytest.TempPathFactory, ulog_data: dict[str, np.ndarray]) -> Path:
    topics = []
    for i in (0, 1):
        accel, accel_temp = ulog_data[f"accel{i}"], ulog_data[f"accel{i}_temp"]
        topics.append(imu_topic("sensor_accel", i, ACCEL_IDS[i], _time_us(100 * i), accel, accel_temp))
        gyro, gyro_temp = ulog_data[f"gyro{i}"], ulog_data[f"gyro{i}_temp"]
        topics.append(imu_topic("sensor_gyro", i, GYRO_IDS[i], _time_us(37 + 100 * i), gyro, gyro_temp))
    baro_time = (5_000_000 + np.arange(N // 5) * 1e6 / 10.0).astype(np.int64)
    topics.append(baro_topic(0, BARO_IDS[0], baro_time, ulog_data["baro0"], ulog_data["baro0_temp"]))
    return write_ulog(tmp_path_factory.mktemp("ulog") / "thermal.ulg", topics)


def run_import(*args: str | Path) -> Recording:
    argv = ["import", *map(str, args)]
    assert main(argv) == 0
    return read_recording(argv[argv.index("-o") + 1])


def import_error(output: Path, *args: str | Path) -> str:
    with pytest.raises(UserError) as caught:
        main(["import", *map(str, args), "-o", str(output)])
    message = str(caught.value)
    assert "\n" not in message and "\x1b" not in message
    assert not output.exists()
    return message


# --------------------------------------------------------------------------- ULog


def test_ulog_reader_returns_every_instance_with_its_temperature(ulog_path: Path, ulog_data: dict) -> None:
    log = read_flight_log(ulog_path)
    assert log.kind == "ulog"
    expected = [f"accel{i}_{a}" for i in (0, 1) for a in "xyz"] + [
        f"gyro{i}_{a}" for i in (0, 1) for a in "xyz"
    ]
    assert list(log.channels) == [*expected, "baro0"]
    for i in (0, 1):
        for k, axis in enumerate("xyz"):
            accel = log.channels[f"accel{i}_{axis}"]
            np.testing.assert_allclose(accel.values, ulog_data[f"accel{i}"][:, k] * 1000.0 / G, rtol=1e-12)
            np.testing.assert_array_equal(accel.temp_c, ulog_data[f"accel{i}_temp"])
            assert accel.device_id == ACCEL_IDS[i]
            np.testing.assert_array_equal(accel.time_us, _time_us(100 * i))  # timestamp_sample, not timestamp
            gyro = log.channels[f"gyro{i}_{axis}"]
            np.testing.assert_allclose(gyro.values, np.degrees(ulog_data[f"gyro{i}"][:, k]), rtol=1e-12)
            np.testing.assert_array_equal(gyro.temp_c, ulog_data[f"gyro{i}_temp"])
            assert gyro.device_id == GYRO_IDS[i]
    baro = log.channels["baro0"]
    np.testing.assert_array_equal(baro.values, ulog_data["baro0"])
    np.testing.assert_array_equal(baro.temp_c, ulog_data["baro0_temp"])
    assert baro.device_id == BARO_IDS[0] and baro.unit == "pa"


@pytest.mark.parametrize("instance", [0, 1])
def test_ulog_each_accel_instance_imports_with_its_temperatures(
    tmp_path: Path, ulog_path: Path, ulog_data: dict, instance: int
) -> None:
    out = tmp_path / f"accel{instance}.csv"
    rec = run_import(ulog_path, "--channel", f"accel{instance}_x", "-o", out)
    assert len(rec) == N
    np.testing.assert_allclose(rec.temp_c, ulog_data[f"accel{instance}_temp"], rtol=1e-9)
    np.testing.assert_allclose(
        rec.accel_mg, ulog_data[f"accel{instance}"][:, 0] * 1000.0 / G, rtol=1e-9, atol=1e-9
    )
    np.testing.assert_allclose(rec.time_s, np.arange(N) / RATE_HZ, atol=1e-9)
    # the sibling axes of the same topic instance come along under the recording-format names
    for k, axis in enumerate("xyz"):
        np.testing.assert_allclose(
            rec.columns[f"accel{instance}_{axis}_mg"],
            ulog_data[f"accel{instance}"][:, k] * 1000.0 / G,
            rtol=1e-9,
        )
    np.testing.assert_allclose(
        rec.columns[f"accel{instance}_temp_c"], ulog_data[f"accel{instance}_temp"], rtol=1e-9
    )
    assert not any(name.startswith("gyro") for name in rec.columns)  # another topic, another time base
    assert rec.meta["channel"] == f"accel{instance}_x"
    assert rec.meta[f"device_id_accel{instance}"] == str(ACCEL_IDS[instance])
    assert float(rec.meta["sample_rate_hz"]) == pytest.approx(RATE_HZ)


def test_ulog_default_channel_is_accel0_z(tmp_path: Path, ulog_path: Path, ulog_data: dict) -> None:
    rec = run_import(ulog_path, "-o", tmp_path / "z.npz")
    assert rec.meta["channel"] == "accel0_z"
    np.testing.assert_allclose(rec.accel_mg, ulog_data["accel0"][:, 2] * 1000.0 / G, rtol=1e-12)
    assert rec.accel_mg.mean() == pytest.approx(-1000.0, abs=1.0)  # gravity as logged


def test_ulog_wrong_channel_lists_the_available_ones(tmp_path: Path, ulog_path: Path) -> None:
    message = import_error(tmp_path / "o.csv", ulog_path, "--channel", "accel2_z")
    assert "'accel2_z' is not in this log" in message
    assert "accel0_x, accel0_y, accel0_z, accel1_x" in message and "baro0" in message
    message = import_error(tmp_path / "o.csv", ulog_path, "--channel", "acc0z")
    assert "not a channel name" in message
    message = import_error(tmp_path / "o.csv", ulog_path, "--channel", "gyro1_x")
    assert "accelerometer axis" in message and "accel1_z" in message


def test_ulog_list_channels(ulog_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["import", str(ulog_path), "--list-channels"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert "PX4 ULog log, 13 channels" in lines[0]
    assert len(lines) == 14
    assert any(line.strip().startswith("gyro1_z [dps]: 60 samples at 50 Hz") for line in lines)
    assert f"device id {BARO_IDS[0]}" in out and "baro0 [pa]: 12 samples at 10 Hz, 25.00 .. 38.00 degC" in out


def test_ulog_column_options_are_refused(tmp_path: Path, ulog_path: Path) -> None:
    message = import_error(tmp_path / "o.csv", ulog_path, "--temp", "T")
    assert "--temp does not apply to a PX4 ULog log" in message


def test_binary_log_never_reaches_the_csv_sniffer(tmp_path: Path, ulog_path: Path) -> None:
    disguised = tmp_path / "looks_like.csv"
    disguised.write_bytes(ulog_path.read_bytes())
    with pytest.raises(UserError, match="a PX4 ULog log, not a delimited text file") as caught:
        import_foreign(disguised, ImportOptions(temp="T", accel="a", time="t"))
    assert "delimiter" not in str(caught.value)
    # the CLI reads it as the log it is, whatever the extension
    rec = run_import(disguised, "-o", tmp_path / "o.csv")
    assert rec.meta["channel"] == "accel0_z"
    other = tmp_path / "blob.txt"
    other.write_bytes(b"t,T,a\n\x00\x01\x02")
    with pytest.raises(UserError, match="binary file"):
        import_foreign(other, ImportOptions(temp="T", accel="a", time="t"))


def test_damaged_ulog_is_one_line(
    tmp_path: Path, ulog_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    damaged = tmp_path / "damaged.ulg"
    damaged.write_bytes(ulog_path.read_bytes()[:20])  # header plus a cut message
    assert run_cli(main, ["import", str(damaged), "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and str(damaged) in err
    assert not (tmp_path / "o.csv").exists()


# --------------------------------------------------------------------------- DataFlash


@pytest.fixture(scope="module")
def dataflash(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, np.ndarray]]:
    writer = DataFlashWriter()
    writer.parm(1000, "INS_ACC_ID", 2753028.0)
    writer.parm(1000, "INS_ACC2_ID", 2883604.0)
    writer.parm(1000, "INS_GYR_ID", 2752772.0)
    writer.parm(1000, "INS_GYR2_ID", 2883348.0)
    writer.parm(1000, "BARO1_DEVID", 65540.0)
    data: dict[str, np.ndarray] = {}
    time_us = _time_us()
    for i in (0, 1):
        data[f"acc{i}"], data[f"gyr{i}"], data[f"T{i}"] = _accel(i), _gyro(i), _ramp(i)
    for row, t in enumerate(time_us):
        for i in (0, 1):
            writer.imu(int(t), i, data[f"gyr{i}"][row], data[f"acc{i}"][row], data[f"T{i}"][row])
        if row % 5 == 0:
            for i in (0, 1):
                writer.baro(int(t) + 10, i, 101325.0 - 10 * i - row, 30.0 + i + row * 0.01)
    data["baro_T1"] = np.array([31.0 + row * 0.01 for row in range(0, N, 5)])
    return writer.write(tmp_path_factory.mktemp("df") / "00000042.BIN"), data


def test_dataflash_reader_returns_every_instance(dataflash: tuple[Path, dict]) -> None:
    path, data = dataflash
    log = read_flight_log(path)
    assert log.kind == "dataflash"
    assert set(log.channels) == {f"{s}{i}_{a}" for s in ("accel", "gyro") for i in (0, 1) for a in "xyz"} | {
        "baro0",
        "baro1",
    }
    for i in (0, 1):
        np.testing.assert_array_equal(log.channels[f"accel{i}_y"].temp_c, data[f"T{i}"])
        np.testing.assert_array_equal(log.channels[f"gyro{i}_y"].temp_c, data[f"T{i}"])
        np.testing.assert_allclose(
            log.channels[f"gyro{i}_z"].values, np.degrees(data[f"gyr{i}"][:, 2]), rtol=1e-12
        )
    assert log.channels["accel1_x"].device_id == 2883604 and log.channels["gyro0_x"].device_id == 2752772
    assert log.channels["baro0"].device_id == 65540 and log.channels["baro1"].device_id is None
    np.testing.assert_allclose(log.channels["baro1"].temp_c, data["baro_T1"], atol=0.0051)  # centi-degC field
    np.testing.assert_allclose(log.channels["baro1"].values[:2], [101315.0, 101310.0])


@pytest.mark.parametrize("instance", [0, 1])
def test_dataflash_each_imu_imports_with_its_temperatures(
    tmp_path: Path, dataflash: tuple[Path, dict], instance: int
) -> None:
    path, data = dataflash
    rec = run_import(path, "--channel", f"accel{instance}_z", "-o", tmp_path / "imu.npz")
    np.testing.assert_array_equal(rec.temp_c, data[f"T{instance}"])
    np.testing.assert_allclose(rec.accel_mg, data[f"acc{instance}"][:, 2] * 1000.0 / G, rtol=1e-12)
    # IMU messages carry accelerometer and gyroscope together: the gyro axes come along
    for k, axis in enumerate("xyz"):
        np.testing.assert_allclose(
            rec.columns[f"gyro{instance}_{axis}_dps"], np.degrees(data[f"gyr{instance}"][:, k]), rtol=1e-12
        )
    np.testing.assert_array_equal(rec.columns[f"gyro{instance}_temp_c"], data[f"T{instance}"])
    assert rec.meta[f"device_id_accel{instance}"] == str([2753028, 2883604][instance])
    assert rec.meta["sensor"] == f"dataflash-accel{instance}_z"
