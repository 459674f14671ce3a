"""Turn a foreign logger's delimited file into a recording (``shared/specs/recording-format.md``).

Loggers disagree on delimiters, column names, time bases and units, and their clocks jitter.
The importer maps named columns onto the contract's ones, converts units, shifts time to start
at 0 and either enforces the 1 % jitter rule or, when asked, resamples every column linearly
onto a uniform grid, or "retimes" (keeps every sample, evens out the timestamps). What it did is
written into the metadata so a recording explains itself.

Why retiming exists: linear interpolation averages neighbouring samples, which lowers white noise
(on the real tofupilot file the sample-to-sample noise drops by about 26 %) and so biases any
noise or Allan-deviation figure. When the timestamps only jitter a little and no sample is
missing, putting the untouched samples on a uniform grid is the firmware's own view of the data:
it counts samples and never reads a clock.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from trainer.data.channels import ALL, DEFAULT_UNIT, names_text
from trainer.data.csv_table import DELIMITER_NAMES, Table, read_table
from trainer.data.flightlog import (
    A_KIND,
    DPS_PER_RADPS,
    MG_PER_MPS2,
    SENSOR_UNITS,
    log_kind,
    parse_channel,
)
from trainer.data.flightlog import STANDARD_GRAVITY as STANDARD_GRAVITY  # re-exported for callers
from trainer.data.plausibility import RATE_MAX_HZ, Plausibility
from trainer.data.recording import Recording, require_rows
from trainer.data.recording_io import JITTER_LIMIT, csv_time_decimals, find_time_problem
from trainer.errors import UserError

# a resampled recording holds at most this many rows (the paper's 2 h at 200 Hz is 1.44 million)
RESAMPLED_ROWS_MAX = 50_000_000

TIME_UNIT_SECONDS: dict[str, float | None] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "index": None}
ACCEL_UNIT_TO_MG: dict[str, float] = {"m/s^2": MG_PER_MPS2, "g": 1000.0, "mg": 1.0}
TEMP_UNIT_OFFSET_C: dict[str, float] = {"degC": 0.0, "K": -273.15}  # added to the column
GYRO_UNIT_TO_DPS: dict[str, float] = {"rad/s": DPS_PER_RADPS, "dps": 1.0}
BARO_UNIT_TO_PA: dict[str, float] = {"Pa": 1.0, "hPa": 100.0}
FILL_TEMP_MODES = ("previous",)
GRAVITY_MODES = ("none", "nominal", "mean")
EXTRA_AXIS_COLUMNS = ("accel_x_mg", "accel_y_mg", "accel_z_mg")
RETIME_MAX_JITTER = 0.05  # --retime refuses larger steps: a lost sample (+100 %) must not be hidden
NOMINAL_GRAVITY_MIN_MG = 500.0  # below this |mean| the axis is not vertical: nominal removal is wrong
SNIFF_LINES = 6  # header plus a few data lines decide the delimiter

Resample = float | Literal["auto"] | None


@dataclass(frozen=True)
class ImportOptions:
    """How to read one foreign file; mirrors the ``trainer import`` options.

    ``resample``: None enforces the jitter rule, a rate in Hz resamples onto that grid, "auto"
    keeps the row count and span (rate = (rows - 1) / span). ``retime``: keep every sample and
    replace its time by ``k * span / (rows - 1)``; only when every step is within
    :data:`RETIME_MAX_JITTER` of the median step.
    """

    temp: str
    accel: str
    time: str | None = None
    time_unit: str = "s"
    rate_hz: float | None = None
    accel_unit: str = "mg"
    extra_axes: tuple[str, str, str] | None = None
    remove_gravity: str = "none"
    sensor: str | None = None
    resample: Resample = None
    retime: bool = False
    delimiter: str | None = None
    meta: dict[str, str] = field(default_factory=dict)
    temp_unit: str = "degC"
    decimal_comma: bool = False
    fill_temp: str | None = None  # "previous": an empty temperature field repeats the last reading
    # Several channels: channel name -> column (a preset's map), and which of them to import.
    channel_map: dict[str, str] = field(default_factory=dict)
    channels: tuple[str, ...] | None = None  # None: the one-axis import; ("all",) or names
    gyro_unit: str = "dps"
    baro_unit: str = "Pa"


# Known loggers: the option values that make their files import with no other flag.
PRESETS: dict[str, dict[str, object]] = {
    # shared/data/real/tofupilot_imu_chamber_cycle.tsv: 7 of 8,399 steps are 1.0-1.09 % long (over
    # the 1 % rule), none is missing, so the samples are kept and retimed onto a uniform grid.
    "tofupilot": {
        "time": "timestamp",
        "time_unit": "us",
        "temp": "imu.temperature",
        "accel": "imu.acc.z",
        "accel_unit": "m/s^2",
        "extra_axes": ("imu.acc.x", "imu.acc.y", "imu.acc.z"),
        "sensor": "tofupilot-imu-acc-z",
        "retime": True,
        "meta": {"channel": "accel0_z", "license": "MIT (c) 2024 tofupilot, see LICENSE.tofupilot"},
        # --channels: the README says gyro in rad/s, acceleration in m/s^2, one temperature for both
        "channel_map": {
            **{f"accel0_{axis}": f"imu.acc.{axis}" for axis in "xyz"},
            **{f"gyro0_{axis}": f"imu.gyro.{axis}" for axis in "xyz"},
        },
        "gyro_unit": "rad/s",
    },
}


def options_with_preset(preset: str | None, **given: object) -> ImportOptions:
    """Options from a preset overridden by the ``given`` values that are not None.

    ``resample`` given (a rate, "auto" or "none") replaces a preset's retiming; "none" means
    neither: the jitter rule is enforced.

    Switching a preset to ``time_unit="index"`` without naming a time column drops the preset's
    time column, so the row number becomes the index.
    """
    values: dict[str, object] = {}
    if preset is not None:
        if preset not in PRESETS:
            raise UserError(f"unknown preset {preset!r}; known: {', '.join(PRESETS)}")
        values.update(PRESETS[preset])
        if given.get("time_unit") == "index" and given.get("time") is None:
            values.pop("time", None)
        if given.get("resample") is not None:
            values.pop("retime", None)
    values.update({key: value for key, value in given.items() if value is not None})
    if values.get("resample") == "none":  # an explicit "enforce the jitter rule" beats the preset
        values["resample"] = None
    values["meta"] = dict(values.get("meta", {}))  # type: ignore[call-overload]
    channel_map: dict[str, str] = {  # a given map adds to (and overrides) the preset's
        **PRESETS.get(preset or "", {}).get("channel_map", {}),  # type: ignore[dict-item]
        **(given.get("channel_map") or {}),  # type: ignore[dict-item]
    }
    values["channel_map"] = channel_map
    if preset is not None and given.get("accel") not in (None, PRESETS[preset].get("accel")):
        # the preset's channel and sensor name describe its own column; another --accel column is
        # another channel (named from the preset's channel map, else left unnamed)
        column = str(given["accel"])
        channel = next((c for c, col in channel_map.items() if col == column), None)
        meta: dict[str, str] = values["meta"]  # type: ignore[assignment]
        if channel is None:
            meta.pop("channel", None)
        else:
            meta["channel"] = channel
        if given.get("sensor") is None and "sensor" in PRESETS[preset]:
            values["sensor"] = f"{preset}-{column.replace('.', '-')}"
    if values.get("channels") is not None:
        values.pop("extra_axes", None)  # the channels replace the older accel_x_mg spelling
    for required in ("temp", "accel"):
        if values.get(required) is None:
            raise UserError(f"--{required} COLUMN is required (or use --preset)")
    if values.get("accel_unit") is None:  # m/s^2 read as mg passes every range check: 100x too small
        raise UserError(
            f"--accel {values['accel']}: give its unit, --accel-unit {'|'.join(ACCEL_UNIT_TO_MG)} (an axis in "
            "m/s^2 read as mg looks like a quiet one in mg, so the file cannot tell)"
        )
    # a gyroscope's rad/s and deg/s (57x), a barometer's Pa and hPa (100x) both look plausible: a
    # channel the user maps takes its unit from the user (or the preset), never from a default
    mapped_by_user = [str(c) for c in given.get("channel_map") or {}]  # type: ignore[attr-defined]
    for sensor, option, units in (
        ("gyro", "gyro_unit", GYRO_UNIT_TO_DPS),
        ("baro", "baro_unit", BARO_UNIT_TO_PA),
    ):
        mapped = [c for c in mapped_by_user if c.startswith(sensor)]
        if mapped and values.get(option) is None:
            raise UserError(
                f"--channel-map maps {mapped[0]}: give its unit, --{option.replace('_', '-')} "
                f"{'|'.join(units)} (the values of both look plausible, so the file cannot tell)"
            )
    return ImportOptions(**values)  # type: ignore[arg-type]


def sniff_delimiter(path: str | Path, *, decimal_comma: bool = False) -> str:
    """Tab, comma or semicolon: the one that splits the header and first data lines alike.

    A known binary log or any file with NUL bytes is refused before it is read as text.
    """
    _refuse_binary(path)
    try:
        with open(path, encoding="utf-8", errors="replace") as handle:
            lines: list[str] = []
            numbers: list[int] = []  # each sniffed line's number in the file
            for number, raw in enumerate(handle, start=1):
                text = raw.strip()
                if text and not text.startswith("#"):
                    lines.append(raw.rstrip("\r\n"))
                    numbers.append(number)
                    if len(lines) == SNIFF_LINES:
                        break
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read ({exc.strerror})") from None
    if not lines:
        raise UserError(f"{path}: no header line (the file is empty or holds only comments)")
    best, best_fields = None, 1
    for candidate in DELIMITER_NAMES:
        if decimal_comma and candidate == ",":
            continue
        counts = {line.count(candidate) for line in lines}
        if len(counts) == 1 and (fields := counts.pop() + 1) > best_fields:
            best, best_fields = candidate, fields
    if (
        best is None
        and decimal_comma
        and len(commas := {line.count(",") for line in lines}) == 1
        and commas.pop()
    ):
        raise UserError(
            f"{path}: line 1 onwards: split alike by commas only, and --decimal-comma reads a comma as the "
            "decimal mark (a comma cannot be both): drop --decimal-comma if the numbers use a point"
        )
    if best is None:
        header = max(DELIMITER_NAMES, key=lambda c: lines[0].count(c))  # ties: the first declared
        fields = lines[0].count(header) + 1
        odd = next((i for i, line in enumerate(lines) if line.count(header) + 1 != fields), None)
        if fields > 1 and odd is not None and odd > 0:  # the header splits, one line does not: say which
            raise UserError(
                f"{path}: line {numbers[odd]}: {lines[odd].count(header) + 1} fields where the header (line "
                f"{numbers[0]}) has {fields}, split by {DELIMITER_NAMES[header]} (a missing or extra field? "
                "else pass --delimiter)"
            )
        raise UserError(
            f"{path}: line 1 onwards: cannot tell the delimiter (tab, comma or semicolon, split alike on "
            f"the first {len(lines)} lines); pass --delimiter"
        )
    return best


def _refuse_binary(path: str | Path) -> None:
    kind = log_kind(path)
    if kind is not None:
        raise UserError(
            f"{path}: {A_KIND[kind]} log, not a delimited text file; import it with --channel NAME "
            f"(the column options do not apply)"
        )
    with open(path, "rb") as handle:
        if b"\0" in handle.read(4096):
            raise UserError(f"{path}: a binary file, not delimited text (NUL bytes in the first 4 kB)")


def import_foreign(path: str | Path, options: ImportOptions, checks: Plausibility | None = None) -> Recording:
    """Read ``path`` and return a recording following ``options``; problems are UserErrors.

    ``checks`` collects plausibility findings (default: the first one is an error).
    """
    _check_options(options)
    checks = checks or Plausibility()
    source = str(path)
    _refuse_binary(path)
    delimiter = options.delimiter or sniff_delimiter(path, decimal_comma=options.decimal_comma)
    extra = list(options.extra_axes or ())
    selected = _selected_channels(options, source)
    wanted = [name for name in (options.time, options.temp, options.accel, *extra) if name is not None]
    wanted += [column for _, column in selected]
    table = read_table(
        path,
        delimiter=delimiter,
        columns=wanted,
        decimal_comma=options.decimal_comma,
        allow_empty=(options.temp,),
        other_delimiter_fix="give the file's delimiter with --delimiter, or leave it out to detect it",
    )
    if len(table) == 0:
        raise UserError(f"{source}: no data rows after the header on line {table.header_line}")
    table, fill_note = _fill_temperature(table, [options.temp], options.fill_temp)
    for name in dict.fromkeys(wanted):
        bad = np.flatnonzero(~np.isfinite(table.columns[name]))
        if bad.size:
            raise UserError(f"{source}: {table.row_label(int(bad[0]))}, column {name!r}: value is not finite")

    checks.accel_declared_g(
        table.columns[options.accel], options.accel_unit, f"{source}: column {options.accel!r}"
    )
    to_mg = ACCEL_UNIT_TO_MG[options.accel_unit]
    with np.errstate(over="ignore"):  # 1e308 m/s^2 becomes inf: refused by the sensor-range check
        columns = {"temp_c": table.columns[options.temp] + TEMP_UNIT_OFFSET_C[options.temp_unit]}
        columns["accel_mg"] = table.columns[options.accel] * to_mg
        for target, name in zip(EXTRA_AXIS_COLUMNS[: len(extra)], extra, strict=True):
            columns[target] = table.columns[name] * to_mg
        for channel, column in selected:
            target, scale = _channel_target(channel, options)
            columns[target] = table.columns[column] * scale
    meta = {"temp_filled": fill_note} if fill_note else {}
    if options.decimal_comma:
        meta["decimal_comma"] = "yes"
    return _finish(table, options, columns, _mapping_note(options, delimiter), meta, checks)


def _selected_channels(options: ImportOptions, source: str) -> list[tuple[str, str]]:
    """(channel, column) pairs ``--channels`` picks from the preset's channel map."""
    if options.channels is None:
        return []
    if not options.channel_map:
        raise UserError(
            f"{source}: --channels needs a channel map for a delimited file (--channel-map accel0_x=COL,... or "
            f"a --preset that has one, e.g. tofupilot); without it import one axis with --accel"
        )
    names = list(options.channel_map) if options.channels == (ALL,) else list(options.channels)
    for name in names:
        if name not in options.channel_map:
            raise UserError(
                f"{source}: --channels {name!r} is not mapped for this file; available: "
                f"{names_text(list(options.channel_map))}"
            )
    return [(name, options.channel_map[name]) for name in names]


def _channel_target(channel: str, options: ImportOptions) -> tuple[str, float]:
    """The recording-format column of ``channel`` and the factor from the file's unit to it."""
    parsed = parse_channel(channel)
    assert parsed is not None, "channel maps hold channel names"
    scale = {
        "accel": ACCEL_UNIT_TO_MG[options.accel_unit],
        "gyro": GYRO_UNIT_TO_DPS[options.gyro_unit],
        "baro": BARO_UNIT_TO_PA[options.baro_unit],
    }[parsed.sensor]
    return f"{channel}_{SENSOR_UNITS[parsed.sensor]}", scale


def _fill_temperature(table: Table, names: list[str], mode: str | None) -> tuple[Table, str | None]:
    """Empty (NaN) temperature cells: an error naming the first, or ``previous`` repeats the last reading.

    Rows before a column's first reading are dropped (there is nothing to repeat).
    """
    missing = {name: np.flatnonzero(np.isnan(table.columns[name])) for name in names}
    missing = {name: rows for name, rows in missing.items() if rows.size}
    if not missing:
        return table, None
    if mode is None:
        name, rows = min(missing.items(), key=lambda item: int(item[1][0]))
        raise UserError(
            f"{table.source}: {table.row_label(int(rows[0]))}, column {name!r}: empty field (a temperature logged "
            f"more slowly than the data? --fill-temp previous repeats the last reading)"
        )
    first = 0
    for name in missing:
        valid = ~np.isnan(table.columns[name])
        if not valid.any():
            raise UserError(f"{table.source}: column {name!r}: no temperature reading at all")
        first = max(first, int(np.argmax(valid)))
    columns = {name: values[first:].copy() for name, values in table.columns.items()}
    filled = 0
    for name in missing:
        values = columns[name]
        index = np.where(np.isnan(values), 0, np.arange(len(values)))
        np.maximum.accumulate(index, out=index)
        filled += int(np.count_nonzero(np.isnan(values)))
        columns[name] = values[index]
    kept = dataclasses.replace(table, columns=columns, lines=table.lines[first:])
    note = f"previous: {filled} empty temperature cells repeat the last reading"
    if first:
        note += f", {first} rows before the first reading dropped"
    return kept, note


def _finish(
    table: Table,
    options: ImportOptions,
    columns: dict[str, np.ndarray],
    mapping: str,
    extra_meta: dict[str, str],
    checks: Plausibility,
) -> Recording:
    """Time base (jitter rule, retime or resample), gravity, plausibility and metadata."""
    source = table.source
    n = len(table)
    require_rows(n, source)  # every time base below (median step, retime, resample) needs a step
    time = _time_seconds(table, options)
    columns = {"time_s": time, **columns}
    checks.temperature(
        columns["temp_c"], f"{source}: column {options.temp!r}", at_import=True, row_label=table.row_label
    )
    checks.recording_ranges(
        columns,
        extra_meta.get("unit", DEFAULT_UNIT),
        source,
        skip=("temp_c",),
        file_names=_source_columns(options),
        row_label=table.row_label,
    )
    meta: dict[str, str] = {}
    time_column = repr(options.time) if options.time else "(row number)"
    if options.retime:
        rate = _retime_rate(time, table, time_column)
        columns["time_s"] = np.arange(n) / rate
        shift = float(np.max(np.abs(columns["time_s"] - time)))
        moved = f"moved by up to {shift:.3g} s ({shift * rate:.2f} periods)"
        meta["retimed_from"] = f"{_jitter_summary(time)}; samples kept, {moved}"
    elif options.resample is not None:
        rate = _resample_rate(options.resample, time, source)
        meta["resampled_from"] = f"{_jitter_summary(time)}; linear interpolation"
        columns = resample_columns(columns, rate)
    else:
        if options.time_unit == "index":
            assert options.rate_hz is not None, "index time needs --rate (checked by _check_options)"
            rate = options.rate_hz
        else:
            rate = _median_rate(time)
        checks.rate(
            rate, f"{source}: column {time_column}", at_import=True, time_units=_other_units(rate, options)
        )
        problem = find_time_problem(np.round(time, csv_time_decimals(time)))
        if problem is not None:
            raise UserError(
                f"{source}: {table.row_label(problem.row)}, column {time_column}: {problem.reason}; "
                f"use --resample HZ (linear interpolation onto a uniform grid) or, when no sample is "
                f"missing, --retime"
            )
    if options.retime or options.resample is not None:
        logged = _median_rate(time)
        checks.rate(
            logged,
            f"{source}: column {time_column}",
            at_import=True,
            time_units=_other_units(logged, options),
        )

    gravity_note = _remove_gravity(columns, options, source)
    meta["sample_rate_hz"] = f"{rate:.10g}"
    if options.sensor:
        meta["sensor"] = options.sensor
    meta["source"] = Path(source).name
    meta["mapping"] = mapping
    if gravity_note:
        meta["gravity_removed"] = gravity_note
    meta.update(extra_meta)
    meta.update(options.meta)
    return Recording(columns, meta, source)


def _other_units(rate_hz: float, options: ImportOptions) -> dict[str, float]:
    """``{--time-unit value: the sample rate it would give}`` for the other units of a time column."""
    declared = TIME_UNIT_SECONDS[options.time_unit]
    if declared is None:  # a row index: its rate is --rate, no unit to change
        return {}
    return {
        unit: rate_hz * declared / scale
        for unit, scale in TIME_UNIT_SECONDS.items()
        if scale is not None and unit != options.time_unit
    }


def _check_options(options: ImportOptions) -> None:
    if options.time_unit not in TIME_UNIT_SECONDS:
        raise UserError(f"--time-unit {options.time_unit!r}: use one of {', '.join(TIME_UNIT_SECONDS)}")
    if options.accel_unit not in ACCEL_UNIT_TO_MG:
        raise UserError(f"--accel-unit {options.accel_unit!r}: use one of {', '.join(ACCEL_UNIT_TO_MG)}")
    if options.remove_gravity not in GRAVITY_MODES:
        raise UserError(f"--remove-gravity {options.remove_gravity!r}: use one of {', '.join(GRAVITY_MODES)}")
    if options.time_unit == "index":
        if options.rate_hz is None:
            raise UserError("--time-unit index needs --rate HZ (the sampling rate of the index)")
    else:
        if options.time is None:
            raise UserError("--time COLUMN is required unless --time-unit index")
        if options.rate_hz is not None:
            raise UserError("--rate only applies to --time-unit index; to change the rate use --resample HZ")
    if options.rate_hz is not None and not (math.isfinite(options.rate_hz) and options.rate_hz > 0):
        raise UserError(f"--rate {options.rate_hz!r}: must be a positive number of Hz")
    rate = options.resample
    if rate is not None and rate != "auto" and not (math.isfinite(float(rate)) and float(rate) > 0):
        raise UserError(f"--resample {options.resample!r}: must be a positive number of Hz or 'auto'")
    if options.retime and options.resample is not None:
        raise UserError("--retime and --resample exclude each other: keep samples or interpolate them")
    if options.extra_axes is not None and len(options.extra_axes) != len(EXTRA_AXIS_COLUMNS):
        raise UserError(f"--extra-axes needs exactly 3 column names (x,y,z), got {len(options.extra_axes)}")
    if options.delimiter is not None and options.delimiter not in DELIMITER_NAMES:
        raise UserError(f"--delimiter {options.delimiter!r}: use tab, comma or semicolon")
    if options.decimal_comma and options.delimiter == ",":
        raise UserError("--decimal-comma needs a tab or semicolon delimiter (a comma cannot be both)")
    if options.temp_unit not in TEMP_UNIT_OFFSET_C:
        raise UserError(f"--temp-unit {options.temp_unit!r}: use one of {', '.join(TEMP_UNIT_OFFSET_C)}")
    if options.gyro_unit not in GYRO_UNIT_TO_DPS:
        raise UserError(f"--gyro-unit {options.gyro_unit!r}: use one of {', '.join(GYRO_UNIT_TO_DPS)}")
    if options.fill_temp is not None and options.fill_temp not in FILL_TEMP_MODES:
        raise UserError(f"--fill-temp {options.fill_temp!r}: use one of {', '.join(FILL_TEMP_MODES)}")


def _time_seconds(table: Table, options: ImportOptions) -> np.ndarray:
    """Time in seconds from 0; the offset is removed in source units to keep integer precision."""
    raw = table.columns[options.time] if options.time is not None else np.arange(len(table), dtype=np.float64)
    scale = TIME_UNIT_SECONDS[options.time_unit]
    if scale is None:
        scale = 1.0 / options.rate_hz  # type: ignore[operator]
    problem = find_time_problem(raw, jitter=False)
    if problem is not None:
        raise UserError(
            f"{table.source}: {table.row_label(problem.row)}, column {options.time!r}: {problem.reason}"
        )
    return (raw - raw[0]) * scale


def _median_rate(time: np.ndarray) -> float:
    return float(1.0 / np.median(np.diff(time)))


def _retime_rate(time: np.ndarray, table: Table, time_column: str) -> float:
    """Rate of the uniform grid with the same row count and span, after checking no sample is lost."""
    steps = np.diff(time)
    median = float(np.median(steps))
    off = np.flatnonzero(np.abs(steps - median) > RETIME_MAX_JITTER * median)
    if off.size:
        step = int(off[0])
        raise UserError(
            f"{table.source}: {table.row_label(step + 1)}, column {time_column}: step {steps[step]:.6g} s "
            f"deviates {100 * abs(steps[step] - median) / median:.1f} % from the median step {median:.6g} s; "
            f"--retime only evens out jitter up to {100 * RETIME_MAX_JITTER:g} % (a lost sample?), "
            f"use --resample HZ"
        )
    return (len(time) - 1) / float(time[-1])


def _resample_rate(resample: float | str, time: np.ndarray, source: str) -> float:
    if resample == "auto":
        return (len(time) - 1) / float(time[-1])
    rate = float(resample)
    rows = float(time[-1] - time[0]) * rate + 1
    if rate > RATE_MAX_HZ or rows > RESAMPLED_ROWS_MAX:
        raise UserError(
            f"{source}: --resample {rate:g} Hz would make {rows:.4g} rows of a {float(time[-1] - time[0]):g} s run "
            f"(at most {RATE_MAX_HZ / 1e3:g} kHz and {RESAMPLED_ROWS_MAX:.0e} rows: the rate is in Hz, "
            f"the run's own is {(len(time) - 1) / float(time[-1] - time[0]):.4g} Hz)"
        )
    return rate


def _jitter_summary(time: np.ndarray) -> str:
    steps = np.diff(time)
    median = float(np.median(steps))
    worst = float(np.max(np.abs(steps - median)) / median)
    late = int(np.count_nonzero(np.abs(steps - median) > JITTER_LIMIT * median))
    return (
        f"{len(time)} rows, steps {steps.min():.6g}..{steps.max():.6g} s (median {median:.6g} s), "
        f"worst jitter {100 * worst:.2f} %, {late} steps over {100 * JITTER_LIMIT:g} %"
    )


def resample_columns(columns: dict[str, np.ndarray], rate: float) -> dict[str, np.ndarray]:
    """Every column linearly interpolated onto ``k / rate`` for all k inside the original span
    (``trainer import --resample`` and ``codegen verify --resample`` share it)."""
    time = columns["time_s"]
    count = math.floor(float(time[-1]) * rate * (1 + 1e-12)) + 1
    grid = np.arange(count) / rate
    resampled = {"time_s": grid}
    for name, values in columns.items():
        if name != "time_s":
            resampled[name] = np.interp(grid, time, values)
    return resampled


def _remove_gravity(columns: dict[str, np.ndarray], options: ImportOptions, source: str) -> str | None:
    """Subtract gravity from accel_mg and from the named column it was read from when the recording
    keeps that too (a flight log's ``accel0_z_mg``: one axis, one value); other axes keep it. Returns
    what was subtracted, from which columns."""
    if options.remove_gravity == "none":
        return None
    accel = columns["accel_mg"]
    mean = float(accel.mean())
    if options.remove_gravity == "mean":
        offset = mean
    else:
        if abs(mean) < NOMINAL_GRAVITY_MIN_MG:
            raise UserError(
                f"{source}: column {options.accel!r}: mean {mean:.1f} mg is not near +-1 g, so "
                f"--remove-gravity nominal does not apply; use mean or none"
            )
        offset = math.copysign(1000.0, mean)
    columns["accel_mg"] = accel - offset
    changed = ["accel_mg"]
    if options.accel and options.accel != "accel_mg" and options.accel in columns:
        columns[options.accel] = columns[options.accel] - offset
        changed.append(options.accel)
    return f"{options.remove_gravity}, subtracted {offset:.10g} mg from {' and '.join(changed)}"


def _source_columns(options: ImportOptions) -> dict[str, str]:
    """``{recording column: the source file's column}`` of the data columns (what a refusal names)."""
    names = {"accel_mg": options.accel} if options.accel else {}
    names.update(zip(EXTRA_AXIS_COLUMNS, options.extra_axes or (), strict=False))
    for channel, column in _selected_channels(options, "<options>"):
        names[_channel_target(channel, options)[0]] = column
    return names


def _mapping_note(options: ImportOptions, delimiter: str) -> str:
    time = f"{options.time}[{options.time_unit}]" if options.time else "row number[index]"
    if options.time_unit == "index":
        time += f" at {options.rate_hz:g} Hz"
    parts = [
        f"time_s<-{time}",
        f"temp_c<-{options.temp}[{options.temp_unit}]",
        f"accel_mg<-{options.accel}[{options.accel_unit}]",
    ]
    for target, name in zip(EXTRA_AXIS_COLUMNS, options.extra_axes or (), strict=False):
        parts.append(f"{target}<-{name}[{options.accel_unit}]")
    for channel, column in _selected_channels(options, "<options>"):
        target, _ = _channel_target(channel, options)
        unit = {"mg": options.accel_unit, "dps": options.gyro_unit, "pa": options.baro_unit}[
            target.rsplit("_", 1)[1]
        ]
        parts.append(f"{target}<-{column}[{unit}]")
    return f"{DELIMITER_NAMES[delimiter]}-delimited; " + " ".join(parts)
