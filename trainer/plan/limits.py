"""What the chamber can do (one record, read by the candidate programs and by the limit check)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from trainer.data.plausibility import TEMP_MAX_C, TEMP_MIN_C
from trainer.errors import UserError


@dataclass(frozen=True)
class ChamberLimits:
    """What the chamber can do: set-point range, fastest ramp, settling after a ramp, longest program."""

    low_c: float = -20.0
    high_c: float = 70.0
    max_rate_c_per_min: float = 2.0
    settling_s: float = 1200.0
    max_duration_s: float = 6 * 3600.0

    def __post_init__(self) -> None:
        for name, value in (("low", self.low_c), ("high", self.high_c)):
            if not TEMP_MIN_C <= value <= TEMP_MAX_C:  # NaN fails too
                raise UserError(
                    f"--range: {name} {value:g} degC is outside {TEMP_MIN_C:g} .. {TEMP_MAX_C:g} degC, the "
                    "temperatures a MEMS sensor and a thermal chamber work at (Kelvin or Fahrenheit?)"
                )
        if not self.high_c > self.low_c:
            swapped = " (swapped? --range LOW_C HIGH_C)" if self.high_c < self.low_c else ""
            raise UserError(f"--range: high {self.high_c:g} must be above low {self.low_c:g} degC{swapped}")
        for name, value in (
            ("--max-rate", self.max_rate_c_per_min),
            ("--settling", self.settling_s),
            ("--max-hours", self.max_duration_s),
        ):
            if not (value > 0 and math.isfinite(value)):
                raise UserError(f"{name} must be a finite number > 0, got {value:g}")
