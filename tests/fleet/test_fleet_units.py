"""``trainer fleet`` on flight-log units, coverage per unit, and failures of the environment.

A small PX4 ULog written by the test (tests/flightlogs.py: one accelerometer and one gyroscope
instance on a monotone 10 -> 50 degC ramp) is the units' recording; the fleet runs on an
in-process Dask cluster (one worker thread) so that a write can be made to fail in the first run.
"""

from __future__ import annotations

import dataclasses
import errno
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.flightlogs import imu_topic, write_ulog
from trainer.checkpoint import load_checkpoint
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import UserError
from trainer.fleet import stages
from trainer.fleet.manifest import load_manifest
from trainer.fleet.result import RESULT_FILE, Failure, UnitResult
from trainer.fleet.run import run_fleet

N = 3000
RATE_HZ = 10.0
TEMP_C = np.linspace(10.0, 50.0, N)  # strictly increasing: the held-out last quarter lies above the rest
GYRO_TEMP_OFFSET_C = 0.5


@pytest.fixture(scope="module")
def ulog(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rng = np.random.default_rng(5)
    time_us = (1_000_000 + np.arange(N) * 1e6 / RATE_HZ).astype(np.int64)
    u = (TEMP_C - 30.0) / 20.0
    noise = 0.001 * rng.normal(size=(N, 3))
    accel = np.column_stack([0.02 + 0.01 * u, 0.01 * u**2, -9.80665 + 0.05 * u + 0.02 * u**3]) + noise
    gyro = np.column_stack([0.002 * u, 0.001 * u**2, 0.003 * u]) + 0.2 * noise
    topics = [
        imu_topic("sensor_accel", 0, 2490378, time_us, accel, TEMP_C),
        imu_topic("sensor_gyro", 0, 2490634, time_us + 37, gyro, TEMP_C + GYRO_TEMP_OFFSET_C),
    ]
    return write_ulog(tmp_path_factory.mktemp("log") / "flight.ulg", topics)


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    """One in-process worker: its tasks see the test's monkeypatches."""
    from distributed import Client, LocalCluster

    with (
        LocalCluster(
            n_workers=1,
            threads_per_worker=1,
            processes=False,
            dashboard_address=None,
            scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"},
        ) as cluster,
        Client(cluster) as active,
    ):
        yield active


def _manifest(directory: Path, ulog: Path, units: str, fleet: str = "") -> Path:
    path = directory / "fleet.toml"
    path.write_text(
        f'[fleet]\nmethods = ["poly3"]\ndiagnose_blocks = 50\n{fleet}\n'
        + units.replace("LOG", str(ulog)).replace("\\", "/")
    )
    return path


FLIGHT_UNITS = """
[[unit]]
id = "A1"
recordings = ["LOG"]
[[unit]]
id = "G1"
recordings = ["LOG"]
import = "--retime --channel gyro0_z"
[[unit]]
id = "ALL"
recordings = ["LOG"]
import = "--channels all"
"""


def test_flight_log_units_are_fitted_and_scored_with_their_coverage(
    tmp_path: Path, ulog: Path, client: Any
) -> None:
    manifest = _manifest(tmp_path, ulog, FLIGHT_UNITS, 'import = "--retime"')
    run = run_fleet(manifest, tmp_path / "out", progress=False, client=client)
    fitted_rows = int(0.75 * N)  # holdout last:0.25: fitted on the first three quarters
    for uid, channel, unit, offset in (("A1", "accel0_z", "mg", 0.0), ("G1", "gyro0_z", "deg/s", 0.5)):
        result = run.results[uid]
        assert result.status == "ok", result.errors
        assert (result.channel, result.unit) == (channel, unit)
        stats = load_checkpoint(run.out_dir / "units" / uid / "poly3" / "model.pt")["train_stats"]
        assert stats["channel"] == channel
        assert stats["temp_min_c"] == pytest.approx(TEMP_C[0] + offset, abs=1e-4)
        assert stats["temp_max_c"] == pytest.approx(TEMP_C[fitted_rows - 1] + offset, abs=1e-4)
        # the scored quarter lies above everything trained on: none of its span is covered
        summary = result.methods["poly3"]
        assert summary["coverage"] == 0.0
        assert summary["scored_range_c"][0] > summary["trained_range_c"][1]
    failed = run.results["ALL"]
    assert failed.status == "failed" and not failed.retry
    (error,) = failed.errors
    for part in ("unit 3 (ALL)", "import '--channels all'", str(ulog), "--channel NAME"):
        assert part in error.error
    report = (run.out_dir / "report.md").read_text()
    # scored entirely above the trained range: the figures judge a held edge value, not the model
    assert "| A1 | REVIEW | accel0_z (mg) | 0 % |" in report
    assert "| G1 | REVIEW | gyro0_z (deg/s) | 0 % |" in report and " deg/s |" in report
    assert (
        "A1 / poly3: scored outside its trained temperature range (0 % of the scored span inside it" in report
    )
    assert "- **A1**: scored" in report and "- **G1**: scored" in report
    fleet = {u["id"]: u for u in json.loads((run.out_dir / "fleet.json").read_text())["units"]}
    assert fleet["A1"]["coverage"] == 0.0 and fleet["G1"]["unit"] == "deg/s"


@pytest.mark.parametrize(
    ("import_text", "log", "expected"),
    [
        ("--temp T", True, "--temp does not apply to a PX4 ULog log"),
        ("--retime", False, "--temp COLUMN is required"),
        ("--preset bogus", False, "argument --preset: invalid choice: 'bogus'"),
    ],
)
def test_import_options_that_cannot_apply_name_unit_file_and_field(
    tmp_path: Path, ulog: Path, import_text: str, log: bool, expected: str
) -> None:
    target = ulog
    if not log:
        target = tmp_path / "run.tsv"
        target.write_text("t\tT\tacc\n0\t20\t1\n")
    manifest = _manifest(
        tmp_path, target, f'[[unit]]\nid = "X1"\nrecordings = ["LOG"]\nimport = "{import_text}"\n'
    )
    with pytest.raises(UserError) as caught:
        load_manifest(manifest)
    message = str(caught.value)
    assert "\n" not in message
    parsed = "invalid choice" not in expected  # options that parse are checked against the file, and name it
    for part in (str(manifest), "unit 1 (X1) import", expected, *([str(target)] if parsed else [])):
        assert part in message
    assert "import import" not in message  # the field named once (argparse's own errors too)


def test_one_line_retries_failures_of_the_environment_only() -> None:
    def raised(exc: BaseException) -> BaseException:
        try:
            try:
                raise exc
            except OSError as inner:
                raise UserError(f"out: cannot write ({inner.strerror})") from None
        except BaseException as outer:
            return outer
        raise AssertionError("unreachable")

    assert stages.one_line(UserError("run.csv: line 3, column 'accel_mg': not a number")) == (
        "run.csv: line 3, column 'accel_mg': not a number",
        False,
    )
    for number in (errno.ENOSPC, errno.EFBIG, errno.EACCES, errno.EROFS):
        message, retry = stages.one_line(raised(OSError(number, "fails")))
        assert retry and message == "out: cannot write (fails)"
    assert stages.one_line(raised(OSError(errno.ENOENT, "gone")))[1] is False  # the unit's own file
    assert stages.one_line(KeyError("x"))[1] is True  # a bug: computed again after the fix


def test_a_full_disk_during_export_is_retried_on_the_next_run(
    tmp_path: Path, ulog: Path, client: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    manifest = _manifest(tmp_path, ulog, '[[unit]]\nid = "A1"\nrecordings = ["LOG"]\n', 'import = "--retime"')
    original = Path.write_text

    def disk_full(self: Path, *args: Any, **kwargs: Any) -> int:
        if self.suffix in (".c", ".h"):  # the generated module: only the export writes these
            raise OSError(errno.ENOSPC, "No space left on device", str(self))
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", disk_full)
    first = run_fleet(manifest, tmp_path / "out", progress=False, client=client)
    result = first.results["A1"]
    assert result.status == "failed" and result.retry
    (error,) = result.errors
    assert error.stage == "export poly3" and "No space left on device" in error.error
    assert json.loads((tmp_path / "out" / "fleet.json").read_text())["units"][0]["sign_off"] == "FAIL"

    monkeypatch.setattr(Path, "write_text", original)  # the disk is fixed
    second = run_fleet(manifest, tmp_path / "out", progress=False, client=client)
    assert second.computed == ["A1"] and second.skipped == []
    again = second.results["A1"]
    assert again.status == "ok" and again.errors == (), again.errors
    assert again.methods["poly3"]["verify"]["passed"]
    third = run_fleet(manifest, tmp_path / "out", progress=False, client=client)
    assert third.computed == [] and third.skipped == ["A1"]  # a finished unit stays cached


def test_a_named_scheduler_is_connected_to_once_per_run(
    tmp_path: Path, ulog: Path, client: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The cluster named by --scheduler is checked before any work and then runs the units: one
    connection (it was opened, closed and opened again)."""
    import trainer.fleet.cluster as cluster

    opened: list[str | None] = []
    original = cluster.open_client

    def counted(scheduler: str | None, workers: int | None, *args: Any) -> Any:
        opened.append(scheduler)
        return original(scheduler, workers, *args)

    monkeypatch.setattr(cluster, "open_client", counted)
    manifest = _manifest(tmp_path, ulog, '[[unit]]\nid = "A1"\nrecordings = ["LOG"]\n', 'import = "--retime"')
    address = client.scheduler.address
    run = run_fleet(manifest, tmp_path / "out", progress=False, scheduler=address)
    assert run.computed == ["A1"] and run.results["A1"].status == "ok"
    assert opened == [address]


def test_a_failed_write_of_the_client_is_one_line_naming_the_path(
    tmp_path: Path, ulog: Path, client: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    manifest = _manifest(tmp_path, ulog, '[[unit]]\nid = "A1"\nrecordings = ["missing.ulg"]\n')
    units = tmp_path / "out" / "units"

    def full(*_: Any) -> Path:
        raise OSError(errno.ENOSPC, "No space left on device", str(units / "A1"))

    monkeypatch.setattr("trainer.fleet.run.publish_unit", full)
    with pytest.raises(UserError) as caught:
        run_fleet(manifest, tmp_path / "out", progress=False, client=client)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(
        f"{units / 'A1'}: cannot write (No space left on device)"
    )


def test_a_result_reads_back_as_written_and_older_results_still_read(tmp_path: Path) -> None:
    """``result.json`` through one record: strict JSON (an unobserved score is null), the same record
    read back, and a file written before ``channel``/``unit``/``import_notes`` existed still reads."""
    error = Failure("method poly3", "no fit", retry=False)
    written = UnitResult(
        id="A1", key="k", status="failed", retry=False, errors=(error,), recordings=("a.csv",),
        evaluated_on="a.csv", export_name="tdc_A1", methods={"poly3": {"drift_left_mg": float("nan")}},
        diagnosis=None, channel="gyro0_z", unit="deg/s", import_notes=("retimed",),
    )  # fmt: skip
    path = tmp_path / RESULT_FILE
    path.write_bytes(written.to_json())
    stored = json.loads(path.read_text())
    assert stored["methods"]["poly3"]["drift_left_mg"] is None
    assert stored["errors"] == [{"stage": "method poly3", "error": "no fit", "retry": False}]
    read = UnitResult.read(path)
    assert read == dataclasses.replace(written, methods={"poly3": {"drift_left_mg": None}})
    older = {k: v for k, v in stored.items() if k not in ("channel", "unit", "import_notes")}
    path.write_text(json.dumps(older))
    assert UnitResult.read(path) == dataclasses.replace(read, channel=None, unit=None, import_notes=())
    path.write_text('{"id": "A1"}')  # damaged: read as no result (the unit is computed again)
    assert UnitResult.read(path) is None


def test_a_channel_of_a_multi_channel_recording_is_chosen_with_import_channel(
    tmp_path: Path, client: Any
) -> None:
    """A spec recording with several channels and no one-axis columns: ``import = "--channel NAME"``
    fits that channel in its unit; without it the unit fails in one line naming the field to give."""
    from trainer.data.channels import channel_view, select_channels
    from trainer.data.recording import Recording
    from trainer.data.recording_io import write_recording

    rng = np.random.default_rng(6)
    u = (TEMP_C - 30.0) / 20.0
    columns = {
        "time_s": np.arange(N) / RATE_HZ,
        "accel0_z_mg": -1000.0 + 5.0 * u + 2.0 * u**3 + 0.05 * rng.normal(size=N),
        "accel0_temp_c": TEMP_C,
        "gyro0_x_dps": 0.1 * u + 0.05 * u**2 + 0.002 * rng.normal(size=N),
        "gyro0_temp_c": TEMP_C + GYRO_TEMP_OFFSET_C,
    }
    path = tmp_path / "imu.npz"
    imu = Recording(columns, {"sample_rate_hz": f"{RATE_HZ:g}"}, "imu")
    write_recording(imu, path)
    # a one-channel file of the gyroscope, as trainer import --channel gyro0_x writes it: no accel_mg
    (gyro,) = select_channels(imu, ("gyro0_x",))
    write_recording(channel_view(imu, gyro), tmp_path / "gyro.npz")
    units = '[[unit]]\nid = "G"\nrecordings = ["LOG"]\nimport = "--channel gyro0_x"\n'
    units += '[[unit]]\nid = "N"\nrecordings = ["LOG"]\n'
    units += f'[[unit]]\nid = "V"\nrecordings = ["{(tmp_path / "gyro.npz").as_posix()}"]\n'
    run = run_fleet(_manifest(tmp_path, path, units), tmp_path / "out", progress=False, client=client)
    assert "accel_mg" not in np.load(tmp_path / "gyro.npz").files
    assert (run.results["V"].status, run.results["V"].channel, run.results["V"].unit) == (
        "ok",
        "gyro0_x",
        "deg/s",
    )
    chosen = run.results["G"]
    assert chosen.status == "ok", chosen.errors
    assert (chosen.channel, chosen.unit) == ("gyro0_x", "deg/s")
    stats = load_checkpoint(run.out_dir / "units" / "G" / "poly3" / "model.pt")["train_stats"]
    assert stats["temp_min_c"] == pytest.approx(TEMP_C[0] + GYRO_TEMP_OFFSET_C)  # the gyro's own thermometer
    (error,) = run.results["N"].errors
    assert error.stage == "load" and 'import = "--channel NAME"' in error.error and "gyro0_x" in error.error


def test_a_delimited_unit_with_channels_fits_the_channel_it_names_or_refuses_several(real_run: Path) -> None:
    """``import = "--preset tofupilot --channels gyro0_x"`` on the bundled run: the unit is gyro x in
    deg/s, not the preset's accelerometer axis (``accel_mg``) it used to score; ``--channels all``
    makes six channels and a unit fits one: refused in one line, as a flight log's is."""
    from trainer.data.channels import channel_unit
    from trainer.data.importer import import_foreign, options_with_preset
    from trainer.fleet.options import UnitImport

    where = "fleet.toml: unit 1 (U1) import"
    rec, _ = UnitImport.parse("--preset tofupilot --channels gyro0_x", where).read(real_run)
    assert channel_unit(rec) == "dps" and rec.meta.get("channel") == "gyro0_x"
    expected = import_foreign(real_run, options_with_preset("tofupilot", channels=("gyro0_x",)))
    np.testing.assert_array_equal(rec.accel_mg, expected.columns["gyro0_x_dps"])
    with pytest.raises(UserError) as caught:
        UnitImport.parse("--preset tofupilot --channels all", where).read(real_run)
    message = str(caught.value)
    assert "\n" not in message and where in message and "makes 6 channels" in message


def test_a_method_worse_than_none_on_the_held_out_part_is_not_exported(tmp_path: Path, client: Any) -> None:
    """As ``codegen export`` refuses it after ``trainer fit --holdout``: a loop that flips sign half-way
    (+k (T - 25) then -k (T - 25)) leaves a cubic fitted on the first half twice no compensation's
    drift on the second. The fleet keeps the model's held-out figures in its model file, writes no C
    for it, and the unit fails the guard."""
    t = np.arange(0.0, 8000.0, 0.5)
    temp = 25.0 + 30.0 * np.sin(2.0 * np.pi * t / 4000.0)
    sign = np.where(t < t[-1] / 2.0, 1.0, -1.0)
    accel = 1000.0 + sign * 0.3 * (temp - 25.0) + np.random.default_rng(5).normal(0.0, 0.05, t.size)
    rec = tmp_path / "flip.csv"
    write_recording(
        Recording({"time_s": t, "temp_c": temp, "accel_mg": accel}, {"sample_rate_hz": "2"}, "flip"), rec
    )
    manifest = tmp_path / "fleet.toml"
    manifest.write_text(
        f'[fleet]\nmethods = ["poly3"]\ndiagnose_blocks = 50\nholdout = "last:0.5"\n'
        f'[[unit]]\nid = "F1"\nrecordings = ["{rec.as_posix()}"]\n'
    )
    run = run_fleet(manifest, tmp_path / "out", progress=False, client=client)
    method = run.out_dir / "units" / "F1" / "poly3"
    record = load_checkpoint(method / "model.pt")["train_stats"]["held_out"]
    assert record["holdout"] == "last:0.5" and record["model_rms"] > 1.5 * record["uncompensated_rms"]
    assert not (method / "c").exists()
    verify = run.results["F1"].methods["poly3"]["verify"]
    assert verify["passed"] is None and "must not reach firmware" in verify["error"]
    assert "| F1 | FAIL |" in (run.out_dir / "report.md").read_text()
