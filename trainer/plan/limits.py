"""What the chamber can do (one record, read by the candidate programs and by the limit check)."""

from __future__ import annotations

from dataclasses import dataclass

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
        if not self.high_c > self.low_c:
            swapped = " (swapped? --range LOW_C HIGH_C)" if self.high_c < self.low_c else ""
            raise UserError(f"--range: high {self.high_c:g} must be above low {self.low_c:g} degC{swapped}")
        for name, value in (
            ("--max-rate", self.max_rate_c_per_min),
            ("--settling", self.settling_s),
            ("--max-hours", self.max_duration_s),
        ):
            if not value > 0:
                raise UserError(f"{name} must be > 0, got {value:g}")
