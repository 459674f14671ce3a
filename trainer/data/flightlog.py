"""Flight-stack logs (PX4 ULog, ArduPilot DataFlash) as named sensor channels.

A flight log holds every sensor instance at its own rate and time base: ``sensor_accel`` and
``sensor_gyro`` are separate ULog topics, a barometer runs slower. So a reader returns *all*
channels, each with its own timestamps, values in the recording format's units (mg, deg/s, Pa)
and its own temperature as logged; picking the channel(s) that become a recording is a separate
step (:func:`trainer.data.importer.import_flight_log`). Channel names follow the "Several
channels" section of ``shared/specs/recording-format.md``: ``accel0_z``, ``gyro1_x``, ``baro0``.

The kind of a file is decided by its magic bytes, never by its extension, so a binary log never
reaches the delimiter sniffer of the CSV importer. The readers live in ``ulog_reader`` and
``dataflash_reader``; :func:`trainer.data.flightlog_io.read_flight_log` picks one.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import re
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import numpy as np

from trainer.errors import SWAPPED_HINT, UserError
from trainer.log_kinds import A_KIND, HEAD_BYTES, KIND_NAMES, kind_of_head

T = TypeVar("T")

STANDARD_GRAVITY = 9.80665  # m/s^2 per g (CGPM 1901)
MG_PER_MPS2 = 1000.0 / STANDARD_GRAVITY
DPS_PER_RADPS = 180.0 / np.pi

KIND_SUFFIXES = {".ulg": "ulog", ".bin": "dataflash"}  # the names these logs are written under

SENSOR_UNITS = {"accel": "mg", "gyro": "dps", "baro": "pa"}  # column unit suffix per sensor
# What a sensor can output, in its unit: beyond it a sample is a fault or a unit mistake, not data
# (the widest full scales of common MEMS IMUs, ICM-42686: +-32 g, +-4000 deg/s; barometers such as
# the MS5611 measure 10 .. 1200 mbar). --accept-implausible takes a sensor beyond them.
SENSOR_RANGES = {"accel": (-32_000.0, 32_000.0), "gyro": (-4000.0, 4000.0), "baro": (1000.0, 120_000.0)}
AXES = ("x", "y", "z")
CHANNEL_NAME = re.compile(r"(accel|gyro)([0-9])_([xyz])|(baro)([0-9])")


@dataclass(frozen=True)
class ChannelName:
    """A parsed channel name: ``accel0_z`` -> (accel, 0, z); ``baro1`` -> (baro, 1, None)."""

    sensor: str
    instance: int
    axis: str | None

    @property
    def unit(self) -> str:
        return SENSOR_UNITS[self.sensor]

    @property
    def temp_column(self) -> str:
        """``accel0_temp_c``: the temperature column the instance's channels share."""
        return f"{self.sensor}{self.instance}_temp_c"


def data_column(channel: str, unit: str) -> str:
    """A channel's data column in the recording format: ``gyro0_x`` in ``dps`` -> ``gyro0_x_dps``."""
    return f"{channel}_{unit}"


def parse_channel(name: str) -> ChannelName | None:
    """The parts of a channel name of the recording format, or None when it is not one."""
    match = CHANNEL_NAME.fullmatch(name)
    if match is None:
        return None
    if match.group(4):
        return ChannelName("baro", int(match.group(5)), None)
    return ChannelName(match.group(1), int(match.group(2)), match.group(3))


@dataclass(frozen=True)
class LogChannel:
    """One sensor axis of one instance: its own time base, values and temperature."""

    sensor: str  # accel | gyro | baro
    instance: int
    axis: str | None  # x | y | z, None for a barometer
    time_us: np.ndarray  # int64 microseconds, the log's own clock
    values: np.ndarray  # float64, in SENSOR_UNITS[sensor]
    temp_c: np.ndarray  # float64, the sensor's own reading as logged (may be NaN)
    device_id: int | None = None

    @property
    def name(self) -> str:
        """``accel0_z``: the data column name of the recording format without its unit."""
        return f"{self.sensor_instance}_{self.axis}" if self.axis else self.sensor_instance

    @property
    def unit(self) -> str:
        return SENSOR_UNITS[self.sensor]

    @property
    def column(self) -> str:
        """The recording-format data column, e.g. ``accel0_z_mg``."""
        return data_column(self.name, self.unit)

    @property
    def temp_column(self) -> str:
        return ChannelName(self.sensor, self.instance, self.axis).temp_column

    @property
    def sensor_instance(self) -> str:
        """``accel0``: the sensor instance, whose channels share one temperature."""
        return f"{self.sensor}{self.instance}"

    def temperature_missing(self) -> str | None:
        """Why the log holds no temperature for this channel, or None when it does.

        Some drivers fill the field with 0 (or NaN) instead of a reading; a drift calibration
        against it would fit nothing, so the import refuses it by name.
        """
        finite = self.temp_c[np.isfinite(self.temp_c)]
        if finite.size == 0:
            return "no temperature logged (the field is empty in every sample)"
        if finite.size == self.temp_c.size and not np.any(finite):
            return f"no temperature logged (0.00 degC in all {finite.size} samples)"
        return None

    def summary(self) -> str:
        """One line for ``trainer import --list-channels``."""
        n = len(self.time_us)
        span_s = (int(self.time_us[-1]) - int(self.time_us[0])) * 1e-6 if n > 1 else 0.0
        rate = f"{(n - 1) / span_s:.4g} Hz" if span_s > 0 else "-"
        finite = self.temp_c[np.isfinite(self.temp_c)]
        temp = self.temperature_missing() or f"{finite.min():.2f} .. {finite.max():.2f} degC"
        device = f", device id {self.device_id}" if self.device_id is not None else ""
        return f"{self.name} [{self.unit}]: {n} samples at {rate}, {temp}{device}"


@dataclass
class FlightLog:
    """Every sensor channel of a log, in a stable order (sensor, instance, axis)."""

    source: str
    kind: str  # a key of trainer.log_kinds.MAGIC
    channels: dict[str, LogChannel]
    notes: dict[str, str] = field(default_factory=dict)  # metadata worth keeping (``key=value``)
    notices: list[str] = field(default_factory=list)  # what the reader changed, printed at import
    missing: str = ""  # why expected sensor data is not among the channels (e.g. sensor_combined only)

    def channel(self, name: str, option: str = "--channel") -> LogChannel:
        """The channel ``name``; a one-line error listing the available ones otherwise (``option``:
        what the user gave it as, ``--channel`` or ``--channels``)."""
        if name not in self.channels:
            if not CHANNEL_NAME.fullmatch(name):
                problem = "is not a channel name (accelN_x|y|z, gyroN_x|y|z, baroN)"
            else:
                problem = "is not in this log"
            hint = f"; {self.missing}" if self.missing else ""
            raise UserError(f"{self.source}: {option} {name!r} {problem}; available: {self.names()}{hint}")
        return self.channels[name]

    def names(self) -> str:
        return ", ".join(self.channels) if self.channels else "(none)"

    def siblings(self, chosen: LogChannel) -> Iterator[LogChannel]:
        """Channels logged at exactly the chosen channel's timestamps (same message or topic)."""
        for other in self.channels.values():
            if len(other.time_us) == len(chosen.time_us) and np.array_equal(other.time_us, chosen.time_us):
                yield other


def time_bases(channels: list[LogChannel]) -> list[list[LogChannel]]:
    """``channels`` grouped by time base (identical timestamps: one topic instance or message).

    A recording has one time column, so each group becomes its own recording; the order of
    ``channels`` is kept within and across groups.
    """
    groups: list[list[LogChannel]] = []
    for channel in channels:
        home = next((g for g in groups if np.array_equal(g[0].time_us, channel.time_us)), None)
        if home is None:
            groups.append([channel])
        else:
            home.append(channel)
    return groups


def group_name(group: list[LogChannel]) -> str:
    """``gyro0``, or ``accel0-gyro0`` for a DataFlash IMU message: the sensor instances of a time base."""
    return "-".join(dict.fromkeys(channel.sensor_instance for channel in group))


def sorted_channels(channels: list[LogChannel]) -> dict[str, LogChannel]:
    order = list(SENSOR_UNITS)
    ranked = sorted(channels, key=lambda c: (order.index(c.sensor), c.instance, c.axis or ""))
    return {c.name: c for c in ranked}


def log_kind(path: str | Path) -> str | None:
    """'ulog', 'dataflash' or None (not a known binary log) from the file's first bytes."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(HEAD_BYTES)
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UserError(f"{path}: is a directory, not a file") from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read ({exc.strerror})") from None
    return kind_of_head(head)


def flight_log_at(path: str | Path) -> str | None:
    """The kind of flight log ``path`` is (an existing file, by its first bytes) or is named as (a
    ``.ulg`` name), else None: where a recording or a model is read or written, such a path is never
    one (``trainer fit -o log.ulg`` overwrote the log with the model)."""
    target = Path(path)
    if target.is_file():
        return log_kind(target)
    return "ulog" if target.suffix.lower() == ".ulg" else None


def refuse_flight_log_output(path: str | Path) -> None:
    """One line, before any work, when the output ``path`` is named as a flight log (``.ulg``) and is
    not one (an existing log is refused for every output by :func:`trainer.errors.check_output_path`)."""
    if (kind := flight_log_at(path)) is not None:
        raise UserError(
            f"{path}: {A_KIND[kind]} log's name for an output that would not be one ({SWAPPED_HINT})"
        )


def quiet_library_call(source: str, kind: str, call: Callable[[], T], notices: list[str] | None = None) -> T:
    """Run a parser that prints and warns, and raises its own exception types.

    What it prints (stdout, stderr) or warns is captured, never forwarded: a damaged log makes the
    readers print thousands of lines. It is summarised in one line, appended to ``notices`` (printed
    once by ``trainer import``) or, when the parser fails, added to the one-line error naming the file;
    the library's exception message is not forwarded either (long, coloured or unsafe advice).
    """
    out = io.StringIO()
    with (
        _captured_fds() as native,
        contextlib.redirect_stdout(out),
        contextlib.redirect_stderr(out),
        warnings.catch_warnings(record=True) as caught,
    ):
        warnings.simplefilter("always")
        try:
            result = call()
        except (MemoryError, KeyboardInterrupt):
            raise
        except Exception as exc:  # the parsers raise many types on damaged files; all mean the same
            failure: str | None = type(exc).__name__
        else:
            failure = None
    summary = library_output_summary(out.getvalue() + "".join(native), caught)
    if failure is not None:
        raise UserError(
            f"{source}: not a readable {KIND_NAMES[kind]} log (truncated or corrupted: {failure})"
            + (f"; {summary}" if summary else "")
        )
    if summary and notices is not None:
        notices.append(f"{source}: {summary}; the damaged parts were skipped")
    return result


@contextlib.contextmanager
def _captured_fds() -> Iterator[list[str]]:
    """Point file descriptors 1 and 2 at a temporary file; its text is in the yielded list on exit.

    pymavlink's Cython indexer prints its "bad header" lines with C stdio, below ``sys.stderr``."""
    text: list[str] = []
    with tempfile.TemporaryFile() as file:
        saved = []
        sys.stdout.flush()
        sys.stderr.flush()
        try:
            for fd in (1, 2):
                saved.append((fd, os.dup(fd)))
                os.dup2(file.fileno(), fd)
            yield text
        finally:
            ctypes.CDLL(None).fflush(None)  # C stdio buffers, before the descriptors go back
            for fd, copy in saved:
                os.dup2(copy, fd)
                os.close(copy)
            file.seek(0)
            text.append(file.read().decode("utf-8", errors="replace"))


SHOWN_CHARS = 80  # of the first captured line, in the summary


def library_output_summary(text: str, caught: list[warnings.WarningMessage]) -> str | None:
    """``the reader printed N lines (first: ...)`` for captured library output, None when silent."""
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    lines += [f"{w.category.__name__}: {w.message}" for w in caught]
    if not lines:
        return None
    first = " ".join(lines[0].split())[:SHOWN_CHARS]  # shown with repr: control codes stay escaped
    return f"the log reader printed {len(lines):,} warning line{'s' if len(lines) != 1 else ''} (first: {first!r})"
