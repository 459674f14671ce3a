"""What the step's integers mean for each channel unit: one int32 LSB is 1/16000 of the unit.

An accelerometer's module reads 1/16 micro-g (16000 LSB = 1 mg); a gyroscope's or barometer's the
same integers in 1/16000 deg/s or 1/16000 Pa. The header, the step's argument names and the run
function's say it in the channel's own words (a gyroscope module once said "acceleration ... +-134 g"
and took ``accel_q4ug``).
"""

from __future__ import annotations

from dataclasses import dataclass

from codegen.quantize import ACCEL_PER_MG

LSB_PER_UNIT = ACCEL_PER_MG  # 16000: 1/16 ug for mg, and the same integers for deg/s and Pa
RANGE_UNITS = (2**31) // LSB_PER_UNIT  # what an int32 holds, in the unit (134217)


@dataclass(frozen=True)
class StepUnits:
    quantity: str  # what goes in and comes out
    argument: str  # the step's input argument
    output: str  # the run function's output array
    label: str  # the unit
    signal: str  # the input briefly (a DLSTM's network input: "(rate - mean deg/s) / std deg/s")

    @property
    def short(self) -> str:
        """One LSB, briefly."""
        return "1/16 ug" if self.label == "mg" else f"1/{LSB_PER_UNIT} {self.label}"

    @property
    def lsb(self) -> str:
        """One LSB, the unit and the int32 range (the header's "Units:" line)."""
        if self.label == "mg":
            return f"1/16 micro-g (Q4 ug: 16 LSB = 1 ug, {LSB_PER_UNIT} LSB = 1 mg, range +-{RANGE_UNITS // 1000} g)"
        return f"1/{LSB_PER_UNIT} {self.label} ({LSB_PER_UNIT} LSB = 1 {self.label}, range +-{RANGE_UNITS} {self.label})"


STEP_UNITS: dict[str, StepUnits] = {
    "mg": StepUnits("acceleration", "accel_q4ug", "out_q4ug", "mg", "accel"),
    "dps": StepUnits("angular rate", "rate_q16k", "out_q16k", "deg/s", "rate"),
    "pa": StepUnits("pressure", "pressure_q16k", "out_q16k", "Pa", "pressure"),
}
