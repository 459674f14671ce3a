"""What the step's integers mean for each channel unit: one int32 LSB is 1/16000 of the unit.

An accelerometer's module reads 1/16 micro-g (16000 LSB = 1 mg); a gyroscope's or barometer's the
same integers in 1/16000 deg/s or 1/16000 Pa. The header, the step's argument names and the run
function's say it in the channel's own words (a gyroscope module once said "acceleration ... +-134 g"
and took ``accel_q4ug``).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StepUnits:
    quantity: str  # what goes in and comes out
    argument: str  # the step's input argument
    output: str  # the run function's output array
    lsb: str  # one LSB, the unit, the int32 range (the header's "Units:" line)
    short: str  # one LSB, briefly


STEP_UNITS: dict[str, StepUnits] = {
    "mg": StepUnits(
        "acceleration",
        "accel_q4ug",
        "out_q4ug",
        "1/16 micro-g (Q4 ug: 16 LSB = 1 ug, 16000 LSB = 1 mg, range +-134 g)",
        "1/16 ug",
    ),
    "dps": StepUnits(
        "angular rate",
        "rate_q16k",
        "out_q16k",
        "1/16000 deg/s (16000 LSB = 1 deg/s, range +-134217 deg/s)",
        "1/16000 deg/s",
    ),
    "pa": StepUnits(
        "pressure",
        "pressure_q16k",
        "out_q16k",
        "1/16000 Pa (16000 LSB = 1 Pa, range +-134217 Pa)",
        "1/16000 Pa",
    ),
}
