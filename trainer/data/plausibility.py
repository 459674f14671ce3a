"""Plausibility checks with hints: the unit and time-base mistakes that import silently.

Each check names what it saw and the likely cause in one line. They run in ``trainer import``
(where the declared units are known) and ``trainer fit`` (on the recording as written). By default
a finding is an error; ``--accept-implausible`` turns it into a one-line warning for the rare
genuine case (a centrifuge run, a sensor in an oven above 150 degC).
"""

from __future__ import annotations

import re
import sys
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

import numpy as np

from trainer.data.flightlog import SENSOR_RANGES, SENSOR_UNITS
from trainer.errors import UserError

if TYPE_CHECKING:
    from trainer.data.recording import Recording
    from trainer.methods import Method

RowLabel = Callable[[int], str]  # a row (from 0) as a message names it: "line 209" of a CSV file
RATE_MIN_HZ = 0.1  # slower than one sample per 10 s: a time column in ms read as s
RATE_MAX_HZ = 100e3  # faster than any MEMS output data rate: s read as ms/us, or an index
LIKELY_RATE_HZ = (0.5, 10e3)  # the rates IMU logs are written at: a time unit giving one is the likely one
TEMP_MAX_C = 150.0  # above any MEMS operating range (-40..125 degC typical)
TEMP_MIN_C = -60.0  # below any MEMS operating range and any thermal chamber's test: an error code
_SENSOR_OF_UNIT = {unit: sensor for sensor, unit in SENSOR_UNITS.items()}
_SENSOR_NOUNS = {"accel": "an accelerometer", "gyro": "a gyroscope", "baro": "a barometer"}
_DATA_COLUMN = re.compile(r"(?!true_).*_(mg|dps|pa)")  # a measured column by its unit suffix
_TEMP_COLUMN = re.compile(r"(?!true_).*_temp_c")  # a channel's own temperature column
KELVIN_RANGE = (200.0, 400.0)  # -73..127 degC written in kelvin
ACCEL_MOVES_MIN_MG = 0.1  # an accelerometer in mg moves by more over a chamber run (accel_moves)
ACCEL_RUN_SPAN_C = 10.0  # ... of at least this temperature span
G_AS_MPS2 = (8.5, 11.0)  # |a| of a static axis carrying gravity when m/s^2 is read as g
ACCEPT_OPTION = "--accept-implausible"
# What to record when the temperature did not move enough (PX4: SDLOG_PROFILE bit 2 "Thermal
# calibration" logs the sensors with their temperatures; ArduPilot: INS_TCALn_ENABLE 2 = LearnCalibration
# fits the cubic on board from the next boot while the IMU warms up to INS_TCALn_TMAX, as
# AP_InertialSensor_tempcal.cpp documents the parameter)
WIDER_RUN_HINT = (
    "record a chamber cycle, or a cold soak then warm-up (PX4: log with SDLOG_PROFILE bit 2, thermal "
    "calibration; ArduPilot: a warm-up log, or on-board learning with INS_TCALn_ENABLE=2 and INS_TCALn_TMAX "
    "the target temperature, then reboot)"
)


class Plausibility:
    """Collects findings; raises on the first one unless ``accept`` (then keeps them as warnings)."""

    def __init__(self, accept: bool = False, way_past: str = f"{ACCEPT_OPTION} to go on anyway") -> None:
        self.accept = accept
        self.way_past = way_past
        self.warnings: list[str] = []

    def problem(self, message: str) -> None:
        if not self.accept:
            raise UserError(f"{message} ({self.way_past})")
        self.warnings.append(message)

    def print_warnings(self) -> None:
        for message in self.warnings:
            print(f"warning: {message}", file=sys.stderr)

    # ---- the checks
    def rate(
        self, rate_hz: float, where: str, *, at_import: bool, time_units: dict[str, float] | None = None
    ) -> None:
        """A sample rate outside 0.1 Hz .. 100 kHz is a time unit read wrongly. At import,
        ``time_units`` (``{--time-unit value: the rate it would give}``) names the likely one."""
        fix = "check --time-unit" if at_import else "check the time unit at import"
        likely = [
            f"--time-unit {unit} gives {rate:.4g} Hz"
            for unit, rate in (time_units or {}).items()
            if LIKELY_RATE_HZ[0] <= rate <= LIKELY_RATE_HZ[1]
        ]
        if likely:
            fix = f"the wrong time unit? ({'; '.join(likely)})"
        if rate_hz < RATE_MIN_HZ:
            cause = "" if likely else "milliseconds read as seconds? "
            self.problem(f"{where}: {rate_hz:.4g} Hz is below {RATE_MIN_HZ:g} Hz: {cause}{fix}")
        elif rate_hz > RATE_MAX_HZ:
            cause = (
                ""
                if likely
                else "microseconds or milliseconds read as seconds, or a sample counter as time? "
            )
            self.problem(f"{where}: {rate_hz:.4g} Hz is above {RATE_MAX_HZ / 1e3:g} kHz: {cause}{fix}")

    def temperature(
        self, temp_c: np.ndarray, where: str, *, at_import: bool, row_label: RowLabel | None = None
    ) -> None:
        """Temperatures above 150 degC; all of them within 200..400 suggests kelvin. A single
        reading out of range is named by its row (``row_label``: the file's line)."""
        hottest, coldest = float(np.max(temp_c)), float(np.min(temp_c))
        if not coldest >= TEMP_MIN_C:
            self.problem(
                f"{_at_row(where, temp_c, coldest, row_label)}: temperature down to {coldest:.4g} degC is below "
                f"{TEMP_MIN_C:g} degC: not a temperature in degC? (a sensor's error value, a raw count or the wrong column)"
            )
        if hottest <= TEMP_MAX_C:
            return
        coldest = float(np.min(temp_c))
        fix = "--temp-unit K" if at_import else "re-import with --temp-unit K"
        if KELVIN_RANGE[0] <= coldest and hottest <= KELVIN_RANGE[1]:
            cause = f"kelvin? ({coldest:.2f} .. {hottest:.2f} K is {coldest - 273.15:.2f} .. {hottest - 273.15:.2f} degC; {fix})"
            self.problem(
                f"{where}: temperature up to {hottest:.4g} degC is above {TEMP_MAX_C:g} degC: {cause}"
            )
            return
        cause = "not a temperature in degC? (kelvin, a raw sensor count or the wrong column)"
        self.problem(
            f"{_at_row(where, temp_c, hottest, row_label)}: temperature up to {hottest:.4g} degC is above "
            f"{TEMP_MAX_C:g} degC: {cause}"
        )

    def sensor_range(
        self, values: np.ndarray, unit: str, where: str, row_label: RowLabel | None = None
    ) -> None:
        """Samples beyond what the sensor of ``unit`` can output (flightlog.SENSOR_RANGES)."""
        sensor = _SENSOR_OF_UNIT[unit]
        lo, hi = SENSOR_RANGES[sensor]
        low, high = float(np.min(values)), float(np.max(values))
        if lo <= low and high <= hi:
            return
        worst = low if low < lo else high
        self.problem(
            f"{_at_row(where, values, worst, row_label)}: {worst:.4g} {unit} is outside the {lo:g} .. {hi:g} {unit} "
            f"{_SENSOR_NOUNS[sensor]} outputs: a "
            f"fault value, a unit mistake (check the declared unit) or the wrong column?"
        )

    def recording_ranges(
        self,
        columns: dict[str, np.ndarray],
        accel_unit: str,
        source: str,
        skip: tuple[str, ...] = (),
        file_names: Mapping[str, str] | None = None,
        row_label: RowLabel | None = None,
    ) -> None:
        """Every measured column against its sensor's range, every temperature column against
        the plausible temperatures (``accel_mg`` holds ``accel_unit``). A refusal names the file's
        column (``file_names``: a column's name in the file, where it differs: a view's ``accel_mg``
        is ``gyro0_x_dps`` there, an import's ``imu.acc.z``) and its row (``row_label``: the line)."""
        for name, values in columns.items():
            if not values.size or name in skip:
                continue
            data = _DATA_COLUMN.fullmatch(name)
            shown = (file_names or {}).get(name, name)
            if name == "accel_mg" or data is not None:
                unit = accel_unit if name == "accel_mg" else data.group(1) if data else accel_unit
                self.sensor_range(values, unit, f"{source}: column {shown!r}", row_label)
            elif name == "temp_c" or _TEMP_COLUMN.fullmatch(name):
                self.temperature(values, f"{source}: column {shown!r}", at_import=False, row_label=row_label)

    def accel_declared_g(self, raw: np.ndarray, unit: str, where: str) -> None:
        """A static axis near 9.8 declared in g is m/s^2."""
        if unit != "g":
            return
        level = float(np.abs(np.median(raw)))
        if G_AS_MPS2[0] <= level <= G_AS_MPS2[1]:
            self.problem(
                f"{where}: median |a| {level:.4g} declared as g (9.8 g at rest?): m/s^2? pass --accel-unit m/s^2"
            )

    def gravity_in_mg(self, accel_mg: np.ndarray, where: str) -> None:
        """A recording whose axis rests near 9.8 g had m/s^2 declared as g at import."""
        level = float(np.abs(np.median(accel_mg))) / 1000.0
        if G_AS_MPS2[0] <= level <= G_AS_MPS2[1]:
            self.problem(
                f"{where}: median |accel_mg| is {level:.4g} g at rest: m/s^2 declared as g at import? "
                f"re-import with --accel-unit m/s^2"
            )

    def output_varies(self, rec: Recording) -> None:
        """A channel that holds one value in every row is no sensor's output."""
        output = np.asarray(rec.accel_mg)
        if output.size and float(np.ptp(output)) == 0.0:
            name = "column 'accel_mg'" if "channel" not in rec.meta else f"channel {rec.meta['channel']}"
            self.problem(
                f"{rec.source}: {name} holds {float(output[0]):g} in every row: no sensor output varies so "
                "little (the wrong column, or a sensor that was not read?)"
            )

    def accel_moves(self, rec: Recording, where: str) -> None:
        """An accelerometer in mg whose output moves by less than 0.1 mg over a run of 10 degC or more
        is in g (1000x too small): every MEMS accelerometer's bias moves by more (0.1 .. 1 mg/degC
        typical), and its noise alone spans more over a run."""
        temp_span_c, moved_mg = float(np.ptp(rec.temp_c)), float(np.ptp(rec.accel_mg))
        if temp_span_c >= ACCEL_RUN_SPAN_C and 0.0 < moved_mg < ACCEL_MOVES_MIN_MG:
            self.problem(
                f"{where}: moves by only {moved_mg:.3g} mg over a {temp_span_c:.3g} degC run, less than any MEMS "
                f"accelerometer's bias and noise: logged in g and read as mg? re-import with --accel-unit g"
            )

    def temperature_span(self, temp_c: np.ndarray, method: str, min_span_c: float, where: str) -> None:
        """A temperature-driven method needs the temperature to move enough to determine its shape."""
        if (short := span_shortfall(temp_c, method, min_span_c)) is not None:
            self.problem(
                f"{where}: {short}: a run without heating or cooling, or the wrong temperature column? "
                f"To calibrate, {WIDER_RUN_HINT}"
            )


def span_shortfall(temp_c: np.ndarray, method: str, min_span_c: float) -> str | None:
    """Why ``temp_c`` spans too little to determine ``method``'s shape in temperature, or ``None``."""
    if min_span_c <= 0:
        return None
    lo, hi = float(np.min(temp_c)), float(np.max(temp_c))
    if hi - lo >= min_span_c:
        return None
    return f"temperature spans {hi - lo:.3g} degC ({lo:.2f} .. {hi:.2f}), too small for {method} (needs {min_span_c:g} degC)"


def _at_row(where: str, values: np.ndarray, worst: float, row_label: RowLabel | None) -> str:
    """``where`` and the first row holding ``worst``: the file's line when known, else its data row."""
    row = int(np.argmax(values == worst))
    return f"{where}, {row_label(row) if row_label is not None else f'data row {row + 1}'}"


def _file_names(rec: Recording, temp_column: str = "temp_c") -> dict[str, str]:
    """The file's names of a (view) recording's one-channel columns (``accel_mg``, ``temp_c``)."""
    return {"accel_mg": rec.file_column(), "temp_c": temp_column}


def check_training(
    rec: Recording, method: Method, *, accept: bool = False, temp_column: str = "temp_c"
) -> Plausibility:
    """The checks ``trainer fit`` runs on a training recording before fitting ``method``
    (``temp_column``: the file's column a channel view reads as ``temp_c``, named in a refusal)."""
    checks = Plausibility(accept)
    where = rec.source
    checks.rate(rec.sample_rate_hz, f"{where}: sample rate", at_import=False)
    unit = rec.meta.get("unit", "mg")
    output_column = rec.file_column()
    checks.recording_ranges(
        rec.columns, unit, where, file_names=_file_names(rec, temp_column), row_label=rec.row_label
    )
    if unit == "mg":  # an accelerometer: gravity, and g read as mg (a gyroscope or barometer holds neither)
        checks.gravity_in_mg(rec.accel_mg, f"{where}: column 'accel_mg'")
        checks.accel_moves(rec, f"{where}: column {output_column!r}")
    checks.output_varies(rec)
    checks.temperature_span(
        rec.temp_c, method.name, method.min_temp_span_c, f"{where}: column {temp_column!r}"
    )
    return checks


def check_scored(rec: Recording) -> Recording:
    """``rec`` unchanged when every sample is one its sensor can output and every temperature one a
    sensor survives, and an accelerometer is in mg (not g read as mg, not m/s^2 read as g); else one
    line. A sample rate outside 0.1 Hz .. 100 kHz (a time unit read wrongly)
    is a warning line. For the commands that score, compare, diagnose or verify a
    recording (they take no ``--accept-implausible``): import and fit refuse such samples too, so
    no model of this tool was made from them without that option."""
    checks = Plausibility(way_past=f"repair or remove those rows; {ACCEPT_OPTION} is for import and fit")
    checks.recording_ranges(
        rec.columns,
        rec.meta.get("unit", "mg"),
        rec.source,
        file_names=_file_names(rec),
        row_label=rec.row_label,
    )
    # what fit refuses is not scored either (a constant channel's Allan figures are nan)
    Plausibility(way_past="trainer fit refuses it too; leave it out of --channels").output_varies(rec)
    if rec.meta.get("unit", "mg") == "mg":  # an accelerometer read in the wrong unit: fit refuses it too
        units = Plausibility(way_past="trainer fit refuses it too")
        units.gravity_in_mg(rec.accel_mg, f"{rec.source}: column 'accel_mg'")
        units.accel_moves(rec, f"{rec.source}: column {rec.file_column()!r}")
    # a warning, not an error: a decimated log may be slow, and these commands have no option to accept it
    time_base = Plausibility(accept=True)
    time_base.rate(rec.sample_rate_hz, f"{rec.source}: sample rate", at_import=False)
    time_base.print_warnings()
    return rec
