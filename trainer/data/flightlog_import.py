"""A PX4 ULog or ArduPilot DataFlash log as recordings: one per time base (``trainer import LOG``).

The readers (:func:`trainer.data.flightlog_io.read_flight_log`) return every sensor channel with
its own timestamps and temperature; this module picks the channels asked for and turns each
time base into a recording with the steps every import shares (temperature filling, jitter rule
or resampling, gravity, plausibility, metadata) from :mod:`trainer.data.importer`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from trainer.data.channels import ALL, DEFAULT_UNIT, names_text
from trainer.data.csv_table import Table
from trainer.data.flightlog import KIND_NAMES, FlightLog, LogChannel, group_name, time_bases
from trainer.data.flightlog_io import read_flight_log
from trainer.data.importer import ImportOptions, Resample, _check_options, _fill_temperature, _finish
from trainer.data.plausibility import Plausibility
from trainer.data.recording import Recording
from trainer.errors import UserError

DEFAULT_CHANNEL = "accel0_z"  # a level board's vertical axis: the one PX4's thermal run sees gravity on


@dataclass(frozen=True)
class LogImportOptions:
    """How to turn a flight log into recordings; mirrors ``trainer import LOG``."""

    channel: str | None = None  # the channel that becomes accel_mg (None: accel0_z, or a time base's own)
    remove_gravity: str = "none"
    sensor: str | None = None
    resample: Resample = None
    retime: bool = False
    fill_temp: str | None = None
    channels: tuple[str, ...] | None = None  # ("all",) or names; None: ``channel`` and its siblings


class _LogTable(Table):
    """A flight log channel and its siblings as a table whose rows are named "sample N"."""

    def row_label(self, row: int) -> str:
        return f"sample {row + 1}"


@dataclass
class LogImport:
    """A flight log's import: one recording per time base (``gyro0``, ``accel0-gyro0``), and notes."""

    recordings: dict[str, Recording]
    notices: list[str] = field(default_factory=list)  # printed: corrections undone, instances left out


def log_output(out: str | Path, group: str, several: bool) -> Path:
    """Where the recording of time base ``group`` goes: ``OUT`` itself, or ``OUT_<group>.ext`` when
    the import made several recordings (``thermal.npz`` -> ``thermal_gyro0.npz``)."""
    path = Path(out)
    return path.with_name(f"{path.stem}_{group}{path.suffix}") if several else path


def import_flight_log(
    path: str | Path, options: LogImportOptions, checks: Plausibility | None = None
) -> LogImport:
    """Channels of a ULog or DataFlash log as recordings, one per time base.

    A sensor instance is logged with its own clock and temperature (a ULog topic instance, a
    DataFlash ``IMU`` message with accelerometer and gyroscope together), and a recording has one
    time column, so each time base becomes its own recording: its main channel (``--channel``, or
    the accelerometer z axis, or the first channel picked) is ``accel_mg`` in the channel's own
    unit (metadata ``channel``, and ``unit`` unless mg) with its temperature as ``temp_c``; every
    channel picked of that time base is kept under its recording-format name.
    """
    checks = checks or Plausibility()
    log = read_flight_log(path)
    groups, notices = _log_groups(log, options)
    if options.remove_gravity != "none" and all(main.sensor != "accel" for main, _ in groups):
        raise UserError(
            f"{log.source}: --remove-gravity applies to an accelerometer axis, and {groups[0][0].name} is a "
            f"{groups[0][0].sensor} channel"
        )
    several = len(groups) > 1
    recordings = {
        group_name(group): _group_recording(log, main, group, options, several, checks)
        for main, group in groups
    }
    return LogImport(recordings, [*log.notices, *notices])


def _log_groups(
    log: FlightLog, options: LogImportOptions
) -> tuple[list[tuple[LogChannel, list[LogChannel]]], list[str]]:
    """(main channel, channels) per time base picked, and one notice per sensor instance left out.

    Without ``--channels``: the ``--channel`` (default accel0_z) and everything logged with it.
    A sensor instance without a temperature is judged on its own, not with its time base (an
    ArduPilot log writes every IMU at the same timestamps: one IMU whose driver reports no
    temperature must not take the others with it): one named (``--channel``, ``--channels``) is an
    error; one only logged beside what was asked, or picked by ``--channels all``, is left out and
    said.
    """
    requested = log.channel(options.channel) if options.channel else None
    everything = options.channels == (ALL,)
    if options.channels is None:
        named = [requested or log.channel(DEFAULT_CHANNEL)]
        groups = [list(log.siblings(named[0]))]
    else:
        picked = (
            list(log.channels.values())
            if everything
            else [log.channel(n, "--channels") for n in options.channels]
        )
        if requested is not None and requested not in picked:
            raise UserError(
                f"{log.source}: --channel {requested.name!r} is not among --channels "
                f"({names_text([c.name for c in picked])}); it names the channel that becomes accel_mg"
            )
        named = ([] if everything else picked) + ([requested] if requested is not None else [])
        groups = time_bases(picked)
    for channel in named:
        if (missing := channel.temperature_missing()) is not None:
            raise UserError(
                f"{log.source}: {channel.sensor_instance}: {missing}: its driver does not report the sensor "
                f"temperature, and a drift calibration is fitted against it"
            )
    kept: list[tuple[LogChannel, list[LogChannel]]] = []
    left_out: dict[str, str] = {}  # sensor instance -> why
    for group in groups:
        with_temperature = []
        for channel in group:
            missing = channel.temperature_missing()
            if missing is None:
                with_temperature.append(channel)
            else:
                left_out.setdefault(channel.sensor_instance, missing)
        if with_temperature:
            main = requested if requested in with_temperature else None
            main = main or next(
                (c for c in with_temperature if c.sensor == "accel" and c.axis == "z"), with_temperature[0]
            )
            kept.append((main, with_temperature))
    if not kept:
        raise UserError(
            f"{log.source}: --channels all: no sensor instance has a temperature: "
            + "; ".join(f"{instance} ({why})" for instance, why in left_out.items())
        )
    notices = [f"{log.source}: left out {instance} ({why})" for instance, why in left_out.items()]
    return kept, notices


def _group_recording(
    log: FlightLog,
    main: LogChannel,
    group: list[LogChannel],
    options: LogImportOptions,
    several: bool,
    checks: Plausibility,
) -> Recording:
    """The recording of one time base, ``main`` as ``accel_mg`` and ``temp_c``."""
    name = group_name(group)
    source = f"{log.source} [{name}]" if several else log.source
    raw: dict[str, np.ndarray] = {"timestamp": main.time_us.astype(np.float64)}
    for channel in group:
        raw[channel.column] = channel.values
        raw[channel.temp_column] = channel.temp_c
    temp_columns = [column for column in raw if column.endswith("_temp_c")]
    n = len(main.time_us)
    table: Table = _LogTable(source, list(raw), 0, raw, np.arange(1, n + 1), {}, {})
    table, fill_note = _fill_temperature(table, temp_columns, options.fill_temp)
    for column, values in table.columns.items():
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise UserError(
                f"{source}: {table.row_label(int(bad[0]))}, channel column {column!r}: value is not finite"
            )
    sensor = options.sensor or f"{log.kind}-{main.name}"
    imported = ImportOptions(
        temp=main.temp_column,
        accel=main.column,
        time="timestamp",
        time_unit="us",
        remove_gravity=options.remove_gravity if main.sensor == "accel" else "none",
        sensor=f"{sensor}-{name}" if several and options.sensor else sensor,
        resample=options.resample,
        retime=options.retime,
    )
    _check_options(imported)
    columns = {"temp_c": table.columns[main.temp_column], "accel_mg": table.columns[main.column]}
    columns.update((column, values) for column, values in table.columns.items() if column != "timestamp")
    meta = {"channel": main.name}
    if main.unit != DEFAULT_UNIT:
        meta["unit"] = main.unit  # the file keeps it in its named column (recording_io.contract_columns)
    for channel in group:
        if channel.device_id is not None:
            meta[f"device_id_{channel.sensor_instance}"] = str(channel.device_id)
    meta.update(log.notes)
    if fill_note:
        meta["temp_filled"] = fill_note
    data = f"accel_mg<-{main.column}" if main.unit == DEFAULT_UNIT else f"one-channel data: {main.column}"
    mapping = (
        f"{KIND_NAMES[log.kind]} log; time_s<-sample time[us] temp_c<-{main.temp_column} "
        f"{data}; kept the {len(group)} channel(s) of its time base"
    )
    rec = _finish(table, imported, columns, mapping, meta, checks)
    rec.meta["source"] = Path(log.source).name  # the file; errors also named the time base
    return rec
