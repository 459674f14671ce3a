"""The raw-input limits per channel unit: one declaration of the ``codegen export`` options that set
where a module whose network reads its raw input (a recursive DLSTM, persistence:
codegen/families/stream/) clamps that input.

Each row of :data:`RAW_INPUT_LIMITS` is one option, the limit of the channels of one unit (the
accelerometers' ``--accel-limit-g`` in g, the gyroscopes' ``--gyro-limit-dps`` in deg/s): its
argparse option and help text (codegen/cli.py), its default, its validation and the LSB value the
quantiser puts into ``codegen.quantize.Limits.signal_lsb``. The limit also sets the stream family's
fixed-point fraction bits (the window sum's bound), so an oversized one wastes precision.

What passes between the command line and the quantiser is a :data:`RawLimits`: channel unit ->
the value given in that unit's option's unit; a unit not in it takes its default.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

from codegen.step_units import LSB_PER_UNIT, STEP_UNITS
from trainer.data.channels import SENSOR_NAMES
from trainer.errors import UserError

# The widest limit, in the channel's unit: 128000 units * 16000 LSB = 2.048e9 LSB < 2**31 (int32).
MAX_LIMIT_UNITS = 128_000

RawLimits = Mapping[str, float]  # channel unit (mg, dps) -> the value in its option's unit
DEFAULT_RAW_LIMITS: RawLimits = MappingProxyType({})  # every unit at its default


@dataclass(frozen=True)
class RawInputLimit:
    """The raw-input limit of the channels of one unit, given as one ``codegen export`` option."""

    unit: str  # the channel unit it governs (a key of codegen.step_units.STEP_UNITS)
    sensor: str  # whose channels those are, in the refusals' words
    option: str  # the command-line option
    option_unit: str  # what the option's value is in
    units_per_option_unit: int  # channel units per option unit (1000 mg per g)
    default: float  # in option_unit
    why: str  # why the default, for the help text

    @property
    def dest(self) -> str:
        """The argparse attribute of the option."""
        return self.option.lstrip("-").replace("-", "_")

    @property
    def maximum(self) -> float:
        """The widest value the option takes (the int32 LSB's bound), in option_unit."""
        return MAX_LIMIT_UNITS / self.units_per_option_unit

    def check(self, value: float) -> float:
        if not (math.isfinite(value) and 0 < value <= self.maximum):
            raise UserError(
                f"{self.option} must be in (0, {self.maximum:g}] {self.option_unit}, got {value:g}"
            )
        return value

    def lsb(self, value: float) -> int:
        """The clamp in the step's LSB (1/16000 of the channel's unit)."""
        return round(self.check(value) * self.units_per_option_unit * LSB_PER_UNIT)

    def value_of(self, lsb: int) -> float:
        """The option's value of a clamp at +-``lsb`` (whose :meth:`lsb` is ``lsb`` again)."""
        return lsb / LSB_PER_UNIT / self.units_per_option_unit

    def help(self) -> str:
        return (
            f"{self.sensor} full scale in {self.option_unit}: a module whose network reads the raw "
            f"{STEP_UNITS[self.unit].quantity} (recursive DLSTM, persistence) clamps it there (default "
            f"{self.default:g}, {self.why}; at most {self.maximum:g}); refused for a module that never clamps it"
        )


RAW_INPUT_LIMITS: dict[str, RawInputLimit] = {
    row.unit: row
    for row in (
        RawInputLimit(
            "mg",
            "accelerometer",
            "--accel-limit-g",
            "g",
            1000,
            16.0,
            "a common MEMS accelerometer full scale",
        ),
        RawInputLimit(
            "dps", "gyroscope", "--gyro-limit-dps", "deg/s", 1, 2000.0, "a common MEMS gyroscope full scale"
        ),
    )
}
# A unit without an option (a barometer's Pa): the trainer refuses the recursive methods on a
# barometer (trainer.data.channels.method_refusal), so only a hand-made model reaches a family that
# clamps its raw input; it is clamped at the widest limit, 128000 Pa, above one atmosphere
# (101325 Pa): a clamp that changes no real pressure.
WIDEST_LSB = MAX_LIMIT_UNITS * LSB_PER_UNIT


def check_raw_limits(given: RawLimits) -> None:
    """Every given value inside its option's range (a one-line UserError otherwise)."""
    for unit, value in given.items():
        if unit not in RAW_INPUT_LIMITS:
            raise ValueError(f"no raw-input limit option for unit {unit!r}")
        RAW_INPUT_LIMITS[unit].check(value)


def signal_lsb(unit: str, given: RawLimits = DEFAULT_RAW_LIMITS) -> int:
    """Where a channel of ``unit`` clamps its raw input, in LSB: the value given for its unit, else
    its option's default (:data:`WIDEST_LSB` for a unit without an option)."""
    check_raw_limits(given)
    row = RAW_INPUT_LIMITS.get(unit)
    if row is None:
        return WIDEST_LSB
    return row.lsb(given.get(unit, row.default))


def add_raw_limit_options(parser: argparse.ArgumentParser) -> None:
    """One option per row of :data:`RAW_INPUT_LIMITS` (default None: not given)."""
    for row in RAW_INPUT_LIMITS.values():
        metavar = row.option.rsplit("-", 1)[1].upper()  # G, DPS
        parser.add_argument(row.option, type=float, default=None, metavar=metavar, help=row.help())


def given_raw_limits(args: argparse.Namespace) -> dict[str, float]:
    """The options given on the command line (checked), unit -> value."""
    given = {
        unit: float(getattr(args, row.dest))
        for unit, row in RAW_INPUT_LIMITS.items()
        if getattr(args, row.dest, None) is not None
    }
    check_raw_limits(given)
    return given


@dataclass(frozen=True)
class RawClamp:
    """Where one channel of a module (or a one-channel module) stands on the raw-input limits."""

    label: str  # how the refusals name it: a channel name, or the model file
    unit: str
    method: str
    clamps: bool  # its network reads its raw input, clamped to the limit of its unit


def check_governed(given: RawLimits, channels: Iterable[RawClamp], *, module: bool) -> None:
    """Refuse, in one line, an option that governs nothing in the export: no channel of its unit
    (``module``: an IMU module's channels; else the one model's), or none of them clamps its raw input."""
    channels = list(channels)
    for unit in given:
        row = RAW_INPUT_LIMITS[unit]
        ours = [c for c in channels if c.unit == unit]
        if not ours:
            if module:
                what = f"the module has none (channels: {', '.join(c.label for c in channels)})"
            else:
                other = channels[0]
                sensor = SENSOR_NAMES[other.unit]
                owner = RAW_INPUT_LIMITS.get(other.unit)
                what = (
                    f"{other.label} is {'an' if sensor[0] in 'aeiou' else 'a'} {sensor} model "
                    f"({STEP_UNITS[other.unit].label}), "
                    + (f"whose option is {owner.option}" if owner else "which has no such option")
                )
            raise UserError(
                f"{row.option}: the option governs the {row.sensor} channels ({STEP_UNITS[unit].label}); {what}"
            )
        if not any(c.clamps for c in ours):
            who = (
                f"none of the module's {row.sensor} channels ({', '.join(f'{c.label} {c.method}' for c in ours)}) "
                "clamps its raw input"
                if module
                else f"a {ours[0].method} module never clamps its raw input"
            )
            raise UserError(
                f"{row.option}: {who}: {'each' if module else 'it'} subtracts the drift from the "
                f"{STEP_UNITS[unit].quantity} as it comes; the option applies to a module whose network reads its input (a recursive DLSTM, "
                f"persistence)"
            )


def raw_limits_of_clamps(clamps: Iterable[tuple[str, int]], where: str) -> dict[str, float]:
    """The options a module was exported with, from where its channels clamp their raw inputs
    ((unit, +-LSB) each, as its manifest states): one limit per unit, channels of one unit at
    different limits refused; a unit without an option must clamp at :data:`WIDEST_LSB`."""
    per_unit: dict[str, set[int]] = {}
    for unit, lsb in clamps:
        per_unit.setdefault(unit, set()).add(lsb)
    given = {}
    for unit, found in per_unit.items():
        label = STEP_UNITS[unit].label
        if len(found) > 1:  # one option per unit: an export gives them one limit
            limits = ", ".join(f"{v / LSB_PER_UNIT:g}" for v in sorted(found))
            raise UserError(
                f"{where}: the {SENSOR_NAMES[unit]} channels clamp their raw inputs at different limits "
                f"({limits} {label})"
            )
        lsb = found.pop()
        row = RAW_INPUT_LIMITS.get(unit)
        if row is None:
            if lsb != WIDEST_LSB:
                raise UserError(
                    f"{where}: the {label} input is clamped at {lsb / LSB_PER_UNIT:g} {label}, this codegen "
                    f"clamps it at {WIDEST_LSB / LSB_PER_UNIT:g} {label} (export the module again)"
                )
            continue
        given[unit] = row.value_of(lsb)
    return given
