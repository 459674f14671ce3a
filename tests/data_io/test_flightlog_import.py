"""``trainer import`` of PX4 ULog and ArduPilot DataFlash logs written by the tests (tests/flightlogs.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.flightlogs import DataFlashWriter, baro_topic, combined_topic, imu_topic, write_ulog
from trainer.cli import main
from trainer.data.channels import recording_channels
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


def test_ulog_gravity_removed_from_the_axis_in_both_its_columns(
    tmp_path: Path, ulog_path: Path, ulog_data: dict
) -> None:
    """--remove-gravity takes 1 g off the imported axis wherever the recording holds it (accel_mg and
    its named column are one axis: a fit of either reads the same values); the other axes keep theirs."""
    rec = run_import(
        ulog_path, "--channels", "accel0_x,accel0_z", "--remove-gravity", "nominal", "-o", tmp_path / "g.csv"
    )
    logged_mg = ulog_data["accel0"] * 1000.0 / G
    assert rec.meta["channel"] == "accel0_z"
    np.testing.assert_allclose(rec.columns["accel0_z_mg"], logged_mg[:, 2] + 1000.0, atol=1e-6)
    np.testing.assert_array_equal(rec.columns["accel0_z_mg"], rec.accel_mg)
    np.testing.assert_allclose(rec.columns["accel0_x_mg"], logged_mg[:, 0], atol=1e-6)
    assert "accel0_z_mg" in rec.meta["gravity_removed"]


def test_ulog_wrong_channel_lists_the_available_ones(tmp_path: Path, ulog_path: Path) -> None:
    message = import_error(tmp_path / "o.csv", ulog_path, "--channel", "accel2_z")
    assert "'accel2_z' is not in this log" in message
    assert "accel0_x, accel0_y, accel0_z, accel1_x" in message and "baro0" in message
    message = import_error(tmp_path / "o.csv", ulog_path, "--channel", "acc0z")
    assert "not a channel name" in message


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


def test_a_ulog_damaged_in_the_middle_says_what_it_may_have_lost(tmp_path: Path) -> None:
    """pyulog skips what it cannot read, which can be everything after the damage: a walk-through
    lost half a log with nothing said but a metadata line. Where pyulog flags the corruption the
    reader says so (``trainer import`` prints its notices), with the time the samples read span."""
    n = 4000  # 200 s at 20 Hz
    time_us = (2_000_000 + np.arange(n) * 50_000).astype(np.int64)
    temp = np.linspace(-10.0, 70.0, n)
    accel = np.column_stack([np.zeros(n), np.zeros(n), -9.80665 + 1e-3 * (temp - 30.0)])
    topics = [
        imu_topic("sensor_accel", 0, ACCEL_IDS[0], time_us, accel, temp),
        imu_topic("sensor_gyro", 0, GYRO_IDS[0], time_us + 37, 1e-3 * accel, temp),  # its own time base
    ]

    def damaged(name: str, log: Path) -> Path:
        data = log.read_bytes()
        half = len(data) // 2
        (tmp_path / name).write_bytes(data[:half] + np.random.default_rng(1).bytes(3000) + data[half:])
        return tmp_path / name

    log = write_ulog(tmp_path / "long.ulg", topics)
    gap = damaged("gap.ulg", log)
    whole, part = read_flight_log(log), read_flight_log(gap)
    notes = [n for n in part.notices if "the file is damaged" in n]
    assert not whole.notices and len(notes) == 1
    assert notes[0].startswith(f"{gap}: the file is damaged and pyulog skipped what it could not read")
    span_s = float(notes[0].split("the samples read span ")[1].split(" s")[0])
    times = [c.time_us for c in part.channels.values()]
    read = (max(t[-1] for t in times) - min(t[0] for t in times)) / 1e6
    assert part.channels["accel0_z"].time_us.size < whole.channels["accel0_z"].time_us.size
    assert span_s == pytest.approx(read, abs=0.05)
    # one topic: the damage garbles a message pyulog keeps, and the refusal says it is the damage (it
    # said "device id changes within the log", a fault of the logging)
    garbled = damaged("garbled.ulg", write_ulog(tmp_path / "alone.ulg", topics[:1]))
    message = import_error(tmp_path / "g.csv", garbled)
    assert message.startswith(f"{garbled}: ") and "(the file is damaged: pyulog skipped" in message


def test_a_flight_log_is_never_read_as_a_recording_nor_overwritten(
    tmp_path: Path, ulog_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``trainer fit -o log.ulg`` overwrote a flight log with the model; a log given where a recording
    is read said "unsupported extension" or, renamed .csv, "not UTF-8 text"."""
    recording = tmp_path / "rec.csv"
    run_import(ulog_path, "-o", recording)
    victim = tmp_path / "victim.ulg"
    victim.write_bytes(ulog_path.read_bytes())
    renamed = tmp_path / "renamed.csv"
    renamed.write_bytes(ulog_path.read_bytes())
    fit = ["fit", "--method", "poly3"]
    cases = [
        (
            [*fit, recording, "-o", victim],
            f"{victim}: a PX4 ULog flight log: the output written there would destroy it",
        ),
        (
            [*fit, recording, "-o", tmp_path / "new.ulg"],
            "a PX4 ULog log's name for an output that would not be one",
        ),
        (
            [*fit, victim, "-o", tmp_path / "m.pt"],
            f"{victim}: a PX4 ULog flight log where a recording (.csv or .npz)",
        ),
        (
            [*fit, renamed, "-o", tmp_path / "m.pt"],
            f"convert it with 'trainer import {renamed} -o NAME.csv' first",
        ),
    ]
    capsys.readouterr()
    for argv, expected in cases:
        assert run_cli(main, [str(a) for a in argv]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and expected in err, err
    assert victim.read_bytes() == ulog_path.read_bytes()
    assert not (tmp_path / "new.ulg").exists() and not (tmp_path / "m.pt").exists()


def test_no_output_of_any_command_is_written_over_a_flight_log(
    tmp_path: Path, ulog_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A flight log is refused as the output of every command, whatever its name: ``trainer diagnose
    --json log.ulg`` (and any output named like a recording or a report) replaced the log."""
    recording = tmp_path / "rec.csv"
    run_import(ulog_path, "-o", recording)
    victims = {name: tmp_path / name for name in ("log.ulg", "log.json", "log.csv", "log.npz", "log.pt")}
    for victim in victims.values():
        victim.write_bytes(ulog_path.read_bytes())
    cases = [
        ["diagnose", recording, "--json", victims["log.ulg"]],
        ["diagnose", recording, "--json", victims["log.json"]],
        ["simulate", "--seed", "1", "--duration", "600", "-o", victims["log.csv"]],
        ["import", ulog_path, "--channel", "accel0_z", "-o", victims["log.npz"]],
        ["fit", "--method", "poly3", recording, "-o", victims["log.pt"]],
    ]
    capsys.readouterr()
    for argv in cases:
        assert run_cli(main, [str(a) for a in argv]) == 2, argv
        err = capsys.readouterr().err
        victim = str(argv[-1])
        assert err.count("\n") == 1, err
        assert err.startswith(f"error: {victim}: a PX4 ULog flight log"), err
    for victim in victims.values():
        assert victim.read_bytes() == ulog_path.read_bytes()


def test_a_channel_of_the_list_is_named_with_the_option_that_listed_it(
    tmp_path: Path, ulog_path: Path
) -> None:
    message = import_error(tmp_path / "o.csv", ulog_path, "--channels", "accel0_z,gyro9_x")
    assert message.startswith(f"{ulog_path}: --channels 'gyro9_x' is not in this log")


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


# --------------------------------------------------------------------------- one recording per sensor instance

GYRO_RATE_HZ = 40.0  # the gyroscopes run on their own clock, at another rate than the accelerometers
THREE_IMU_IDS = {"accel": 1000, "gyro": 2000}  # + instance


def _three_imu_log(path: Path, *, gyro2_temp_zero: bool = False) -> tuple[Path, dict[str, np.ndarray]]:
    """Three IMUs, each accelerometer and gyroscope its own topic instance with its own clock and temperature."""
    data: dict[str, np.ndarray] = {}
    topics = []
    for i in (0, 1, 2):
        data[f"accel{i}_time"] = _time_us(100 * i)
        data[f"gyro{i}_time"] = (5_000_053 + 100 * i + np.arange(N) * 1e6 / GYRO_RATE_HZ).astype(np.int64)
        data[f"accel{i}"], data[f"accel{i}_temp"] = _accel(i), _ramp(i)
        data[f"gyro{i}"], data[f"gyro{i}_temp"] = _gyro(i), _ramp(i) + 0.5
        if gyro2_temp_zero and i == 2:
            data["gyro2_temp"] = np.zeros(N)  # a driver that does not report its temperature
        for sensor in ("accel", "gyro"):
            topics.append(
                imu_topic(
                    f"sensor_{sensor}",
                    i,
                    THREE_IMU_IDS[sensor] + i,
                    data[f"{sensor}{i}_time"],
                    data[f"{sensor}{i}"],
                    data[f"{sensor}{i}_temp"],
                )
            )
    return write_ulog(path, topics), data


@pytest.fixture(scope="module")
def three_imu(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, np.ndarray]]:
    return _three_imu_log(tmp_path_factory.mktemp("imu3") / "three.ulg")


def _expected(data: dict[str, np.ndarray], sensor: str, instance: int, k: int) -> np.ndarray:
    values = data[f"{sensor}{instance}"][:, k]
    return values * 1000.0 / G if sensor == "accel" else np.degrees(values)


def test_ulog_gyro_channel_alone_is_its_own_recording(tmp_path: Path, three_imu: tuple[Path, dict]) -> None:
    path, data = three_imu
    rec = run_import(path, "--channel", "gyro0_x", "-o", tmp_path / "g.csv")
    # the format keeps accel_mg for milli-g: the file holds deg/s only under gyro0_x_dps, which a
    # one-channel command reads as its data (the metadata name the channel)
    assert "accel_mg" not in rec.columns
    header = next(line for line in (tmp_path / "g.csv").read_text().splitlines() if not line.startswith("#"))
    assert "accel_mg" not in header.split(",") and "gyro0_x_dps" in header.split(",")
    np.testing.assert_allclose(rec.accel_mg, _expected(data, "gyro", 0, 0), rtol=1e-9)  # deg/s, its data
    np.testing.assert_allclose(rec.temp_c, data["gyro0_temp"], rtol=1e-9)  # the gyroscope's own temperature
    np.testing.assert_allclose(rec.time_s, np.arange(N) / GYRO_RATE_HZ, atol=1e-9)  # its own clock
    assert float(rec.meta["sample_rate_hz"]) == pytest.approx(GYRO_RATE_HZ)
    assert (rec.meta["channel"], rec.meta["unit"]) == ("gyro0_x", "dps")
    assert rec.meta["device_id_gyro0"] == str(THREE_IMU_IDS["gyro"])
    assert list(recording_channels(rec)) == ["gyro0_x", "gyro0_y", "gyro0_z"]
    for k, axis in enumerate("xyz"):
        np.testing.assert_allclose(rec.columns[f"gyro0_{axis}_dps"], _expected(data, "gyro", 0, k), rtol=1e-9)


def test_ulog_gyro_only_channel_set(tmp_path: Path, three_imu: tuple[Path, dict]) -> None:
    path, data = three_imu
    out = tmp_path / "g1.npz"
    rec = run_import(path, "--channels", "gyro1_x,gyro1_y,gyro1_z", "-o", out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g1.npz"]  # one time base: OUT itself
    assert list(recording_channels(rec)) == ["gyro1_x", "gyro1_y", "gyro1_z"]
    np.testing.assert_array_equal(rec.columns["gyro1_temp_c"], data["gyro1_temp"])
    np.testing.assert_allclose(rec.columns["gyro1_z_dps"], _expected(data, "gyro", 1, 2), rtol=1e-12)
    assert rec.meta["channel"] == "gyro1_x" and rec.meta["unit"] == "dps"


def test_ulog_mixed_channels_one_recording_per_sensor_resampled(
    tmp_path: Path, three_imu: tuple[Path, dict], capsys: pytest.CaptureFixture[str]
) -> None:
    path, data = three_imu
    rate_hz = 20.0
    assert (
        main(
            [
                "import",
                str(path),
                "--channels",
                "accel0_z,gyro0_x",
                "--resample",
                "20",
                "-o",
                str(tmp_path / "m.npz"),
            ]
        )
        == 0
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m_accel0.npz", "m_gyro0.npz"]
    out = capsys.readouterr().out
    assert "m_accel0.npz: 24 rows at 20 Hz (resampled)" in out and "m_gyro0.npz: 30 rows at 20 Hz" in out
    for sensor, k in (("accel", 2), ("gyro", 0)):
        rec = read_recording(tmp_path / f"m_{sensor}0.npz")
        time_s = (data[f"{sensor}0_time"] - data[f"{sensor}0_time"][0]) * 1e-6  # its own clock
        grid = np.arange(int(np.floor(time_s[-1] * rate_hz + 1e-9)) + 1) / rate_hz
        np.testing.assert_allclose(rec.time_s, grid, atol=1e-12)
        np.testing.assert_allclose(
            rec.accel_mg, np.interp(grid, time_s, _expected(data, sensor, 0, k)), rtol=1e-9
        )
        np.testing.assert_allclose(rec.temp_c, np.interp(grid, time_s, data[f"{sensor}0_temp"]), rtol=1e-9)
        assert list(recording_channels(rec)) == [f"{sensor}0_{'xyz'[k]}"]


def test_ulog_channels_all_brings_every_imu_instance(tmp_path: Path, three_imu: tuple[Path, dict]) -> None:
    path, data = three_imu
    assert main(["import", str(path), "--channels", "all", "-o", str(tmp_path / "a.csv")]) == 0
    groups = [f"{s}{i}" for s in ("accel", "gyro") for i in (0, 1, 2)]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f"a_{g}.csv" for g in groups)
    for sensor in ("accel", "gyro"):
        for i in (0, 1, 2):
            rec = read_recording(tmp_path / f"a_{sensor}{i}.csv")
            assert list(recording_channels(rec)) == [f"{sensor}{i}_{a}" for a in "xyz"]
            np.testing.assert_allclose(
                rec.columns[f"{sensor}{i}_temp_c"], data[f"{sensor}{i}_temp"], rtol=1e-9
            )
            for k, axis in enumerate("xyz"):
                unit = "mg" if sensor == "accel" else "dps"
                np.testing.assert_allclose(
                    rec.columns[f"{sensor}{i}_{axis}_{unit}"],
                    _expected(data, sensor, i, k),
                    rtol=1e-9,
                    atol=1e-9,
                )
            assert rec.meta["channel"] == (f"accel{i}_z" if sensor == "accel" else f"gyro{i}_x")
            assert rec.meta[f"device_id_{sensor}{i}"] == str(THREE_IMU_IDS[sensor] + i)


def test_instance_without_temperature_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = _three_imu_log(tmp_path / "zero.ulg", gyro2_temp_zero=True)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    assert main(["import", str(path), "--channels", "all", "-o", str(out_dir / "a.npz")]) == 0
    names = sorted(p.name for p in out_dir.iterdir())
    assert "a_gyro2.npz" not in names and len(names) == 5
    out = capsys.readouterr().out
    assert f"note: {path}: left out gyro2 (no temperature logged (0.00 degC in all {N} samples))" in out
    message = import_error(out_dir / "g2.csv", path, "--channel", "gyro2_x")
    assert f"gyro2: no temperature logged (0.00 degC in all {N} samples)" in message
    assert main(["import", str(path), "--list-channels"]) == 0
    assert "gyro2_x [dps]: 60 samples at 40 Hz, no temperature logged" in capsys.readouterr().out


def test_an_imu_without_temperature_does_not_take_the_others_of_its_time_base(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """ArduPilot writes every IMU at the same timestamps, so both IMUs share one time base. IMU1's
    driver reports 0 degC: IMU1 is left out (or refused when named) and IMU0 is imported as it would
    be alone (its whole time base was refused, by default and under ``--channels all``)."""
    writer = DataFlashWriter()
    acc, gyr, temp = _accel(0), _gyro(0), _ramp(0)
    for row, t in enumerate(_time_us()):
        writer.imu(int(t), 0, gyr[row], acc[row], temp[row])
        writer.imu(int(t), 1, _gyro(1)[row], _accel(1)[row], 0.0)
    path = writer.write(tmp_path / "00000007.BIN")
    note = f"note: {path}: left out {{}} (no temperature logged (0.00 degC in all {N} samples))"
    for extra, output in (((), "z.npz"), (("--channels", "all"), "all.npz")):
        capsys.readouterr()
        assert main(["import", str(path), *extra, "-o", str(tmp_path / output)]) == 0
        rec = read_recording(tmp_path / output)  # one time base left: written under the name asked
        assert rec.meta["channel"] == "accel0_z"
        assert list(recording_channels(rec)) == [f"{s}0_{a}" for s in ("accel", "gyro") for a in "xyz"]
        np.testing.assert_allclose(rec.temp_c, temp, rtol=1e-9)
        np.testing.assert_allclose(rec.columns["accel0_x_mg"], _accel(0)[:, 0] / G * 1000.0, rtol=1e-6)
        out = capsys.readouterr().out
        assert note.format("accel1") in out and note.format("gyro1") in out
    for named in (("--channel", "gyro1_x"), ("--channels", "accel0_z,accel1_z")):
        message = import_error(tmp_path / "named.npz", path, *named)
        assert f"1: no temperature logged (0.00 degC in all {N} samples)" in message


def test_older_px4_log_with_sensor_combined_only_says_what_to_log(tmp_path: Path) -> None:
    time_us = _time_us()
    combined = combined_topic(time_us, _gyro(0), _accel(0))
    old = write_ulog(tmp_path / "sample.ulg", [combined])
    message = import_error(tmp_path / "o.csv", old)
    assert "without accelerometer, gyroscope or barometer channels" in message
    assert f"only in sensor_combined ({N} samples), which carries no sensor temperature" in message
    assert "sensor_accel and sensor_gyro with their temperature" in message
    assert "thermal calibration profile" in message and "SDLOG_PROFILE" in message
    with pytest.raises(UserError, match="only in sensor_combined"):
        main(["import", str(old), "--list-channels"])
    # with a barometer logged, the IMU channels asked for are missing for the same reason
    baro = baro_topic(0, 1, time_us[::5], np.full(N // 5, 101325.0), np.linspace(25.0, 30.0, N // 5))
    with_baro = write_ulog(tmp_path / "baro.ulg", [combined, baro])
    message = import_error(tmp_path / "o.csv", with_baro)
    assert (
        "'accel0_z' is not in this log; available: baro0; its IMU data is only in sensor_combined" in message
    )


def test_ulog_gyro_recording_gives_px4_tc_g_parameters(tmp_path: Path) -> None:
    """The point of importing a gyroscope: import -> fit poly3 -> TC_G0_* for PX4, keyed by its device id."""
    from codegen.cli import main as codegen_main

    n = 200
    temp_c = np.linspace(10.0, 60.0, n)
    slope, curve = 1e-4, 2e-6  # rad/s per degC, per degC^2 about 35 degC
    gyro = np.column_stack([0.002 + slope * (temp_c - 35.0) + curve * (temp_c - 35.0) ** 2] * 3)
    time_us = (5_000_000 + np.arange(n) * 1e6 / GYRO_RATE_HZ).astype(np.int64)
    accel = np.column_stack([np.zeros(n), np.zeros(n), np.full(n, -G)])
    path = write_ulog(
        tmp_path / "gyro.ulg",
        [
            imu_topic("sensor_accel", 0, 111, time_us + 7, accel, temp_c),  # another topic, another recording
            imu_topic("sensor_gyro", 0, 222, time_us, gyro, temp_c),
        ],
    )
    assert (
        main(["import", str(path), "--channels", "gyro0_x,gyro0_y,gyro0_z", "-o", str(tmp_path / "g.npz")])
        == 0
    )
    assert (
        main(
            [
                "fit",
                str(tmp_path / "g.npz"),
                "--channels",
                "all",
                "--method",
                "poly3",
                "-o",
                str(tmp_path / "fit"),
            ]
        )
        == 0
    )
    argv = ["export", str(tmp_path / "fit"), "--channels", "all", "-o", str(tmp_path / "params")]
    assert codegen_main([*argv, "--format", "px4-params"]) == 0
    rows = [
        line.split("\t") for line in next((tmp_path / "params").glob("*.params")).read_text().splitlines()
    ]
    values = {row[2]: float(row[3]) for row in rows if not row[0].startswith("#")}
    assert values["TC_G_ENABLE"] == 1 and values["TC_G0_ID"] == 222 and "TC_A0_ID" not in values
    t_ref = values["TC_G0_TREF"]
    for axis in (0, 1, 2):  # the drift re-expanded about TREF: X1 = slope + 2 curve (TREF - 35), X2 = curve
        assert values[f"TC_G0_X1_{axis}"] == pytest.approx(slope + 2 * curve * (t_ref - 35.0), rel=1e-3)
        assert values[f"TC_G0_X2_{axis}"] == pytest.approx(curve, rel=1e-3)


# --------------------------------------------------------------------------- ArduPilot INS_TCAL in the log

TCAL_T_MIN_C, TCAL_T_MAX_C = 15.0, 55.0
CALTEMP_C = {"accel": 24.0, "gyro": 31.0}


def _drift(sensor: str, temp_c: np.ndarray) -> np.ndarray:
    """The raw drift (m/s^2, rad/s) per axis: a cubic of the temperature, shape (n, 3)."""
    d = (temp_c[:, None] - 30.0) / 20.0
    scale = 0.2 if sensor == "accel" else 0.01
    return scale * (
        np.array([0.3, -0.5, 0.8]) * d + np.array([0.2, 0.1, -0.4]) * d**2 + np.array([-0.1, 0.3, 0.2]) * d**3
    )


def _tcal_parameters() -> dict[str, float]:
    """The drift as INS_TCAL1_* written by codegen's own ArduPilot exporter (the convention to invert)."""
    from codegen.flightparams import ChannelCubic, render_ardupilot
    from trainer.data.flightlog import parse_channel

    cubics = []
    temps = np.linspace(0.0, 80.0, 9)
    for sensor in ("accel", "gyro"):
        drift = _drift(sensor, temps)
        for k, axis in enumerate("xyz"):
            coefficients = np.polynomial.polynomial.polyfit(temps - 30.0, drift[:, k], 3)  # exact: a cubic
            name = f"{sensor}0_{axis}"
            channel = parse_channel(name)
            assert channel is not None
            cubics.append(
                ChannelCubic(channel, name, None, coefficients, 30.0, TCAL_T_MIN_C, TCAL_T_MAX_C, "0")
            )
    lines = [line.split() for line in render_ardupilot(cubics).splitlines() if not line.startswith("#")]
    return {name: float(value) for name, value in lines}


def _tcal_log(
    path: Path, orientation: int = 0, changed: dict[str, float] | None = None
) -> tuple[Path, dict[str, np.ndarray]]:
    params = _tcal_parameters()
    assert params["INS_TCAL1_ENABLE"] == 1.0
    writer = DataFlashWriter()
    for name, value in params.items():
        writer.parm(1000, name, value)
    for name, value in (changed or {}).items():  # set again later in the log
        writer.parm(2000, name, value)
    writer.parm(1000, "INS_ACC1_CALTEMP", CALTEMP_C["accel"])
    writer.parm(1000, "INS_GYR1_CALTEMP", CALTEMP_C["gyro"])
    writer.parm(1000, "AHRS_ORIENTATION", float(orientation))
    temp_c = np.linspace(5.0, 65.0, N).astype(np.float32).astype(np.float64)  # beyond TMIN..TMAX: clamped
    clamped = np.clip(temp_c, TCAL_T_MIN_C, TCAL_T_MAX_C)
    data = {"T": temp_c}
    for sensor, base in (("accel", np.array([0.05, -0.02, -G])), ("gyro", np.array([0.001, 0.002, -0.003]))):
        data[f"raw_{sensor}"] = base + _drift(sensor, temp_c)
        # what ArduPilot logs: raw - (drift(T') - drift(CALTEMP')), written independently of the parameters
        cal = np.clip(np.array([CALTEMP_C[sensor]]), TCAL_T_MIN_C, TCAL_T_MAX_C)
        data[f"logged_{sensor}"] = data[f"raw_{sensor}"] - (_drift(sensor, clamped) - _drift(sensor, cal))
    for row, t in enumerate(_time_us()):
        writer.imu(int(t), 0, data["logged_gyro"][row], data["logged_accel"][row], temp_c[row])
        writer.imu(int(t), 1, data["raw_gyro"][row], data["raw_accel"][row], temp_c[row])  # INS_TCAL2 off
    return writer.write(path), data


def test_dataflash_tcal_correction_is_removed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, data = _tcal_log(tmp_path / "tcal.bin")
    out = tmp_path / "imus.npz"  # ArduPilot logs every IMU at the same TimeUS: one time base, one file
    assert main(["import", str(path), "--channels", "all", "-o", str(out)]) == 0
    assert "IMU 0 was logged with INS_TCAL1_ENABLE=1 (already compensated)" in capsys.readouterr().out
    rec = read_recording(out)
    assert rec.meta["tcal_removed_imu0"] and "tcal_removed_imu1" not in rec.meta
    for instance in (0, 1):
        for sensor, unit, to_unit, tol in (
            ("accel", "mg", 1000.0 / G, 2e-3),
            ("gyro", "dps", 180 / np.pi, 1e-5),
        ):
            raw = data[f"raw_{sensor}"] * to_unit
            logged = data[f"logged_{sensor}"] * to_unit
            for k, axis in enumerate("xyz"):
                restored = rec.columns[f"{sensor}{instance}_{axis}_{unit}"]
                # float32 logging and parameters: within tol of the raw reading, far from the logged one
                np.testing.assert_allclose(restored, raw[:, k], atol=tol, rtol=0)
                if instance == 0:  # corrected before logging: the restored data are not the logged ones
                    assert np.max(np.abs(restored - logged[:, k])) > 100 * tol


def test_dataflash_tcal_with_board_orientation_is_refused(tmp_path: Path) -> None:
    path, _ = _tcal_log(tmp_path / "rotated.bin", orientation=2)
    message = import_error(tmp_path / "o.csv", path, "--channel", "accel0_z")
    assert "INS_TCAL1_ENABLE=1" in message and "AHRS_ORIENTATION=2" in message and "sensor frame" in message


@pytest.mark.parametrize(
    ("changed", "expected"),
    [
        ({"INS_TCAL1_ACC2_Z": 1.0}, "parameter INS_TCAL1_ACC2_Z changes during the log"),
        ({"INS_TCAL1_ENABLE": 0.0}, "INS_TCAL1_ENABLE changes during the log"),
    ],
)
def test_dataflash_tcal_changed_during_the_log_is_refused(
    tmp_path: Path, changed: dict[str, float], expected: str
) -> None:
    path, _ = _tcal_log(tmp_path / "changed.bin", changed=changed)
    assert expected in import_error(tmp_path / "o.csv", path)
