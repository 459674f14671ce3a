"""Chamber programs in the catalogue's profile vocabulary: the standard ones and the candidate designs.

A program is what ``[protocol] name = "custom"`` holds (``trainer simulate --config``): a start
set-point (in equilibrium) and ``soak``/``ramp_up``/``hold``/``ramp_down`` segments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import product
from typing import TYPE_CHECKING

from trainer.physics.config import ProtocolConfig
from trainer.physics.profiles import PAPER_OVEN, SegmentSpec

if TYPE_CHECKING:
    from trainer.plan.limits import ChamberLimits

# The bundled real run (shared/data/real): from 52 degC down to -17.6 at 3.05 degC/min, up to 74.0 at
# 3.10, down to 36.0 at 2.05 (cooling 0-1363 s, heating 1364-3133 s, cooling 3134-4245 s), no holds.
BUNDLED_CYCLE: tuple[float, tuple[SegmentSpec, ...]] = (
    52.0,
    (
        SegmentSpec("ramp_down", 1363.0, -17.6),
        SegmentSpec("ramp_up", 1770.0, 74.0),
        SegmentSpec("ramp_down", 1111.0, 36.0),
    ),
)
# A warm-up from cold (PX4's on-board calibration): the board warms itself with a 20 min time
# constant from the cold end towards the hot end, sampled every 15 min for an hour.
WARMUP_TAU_S = 1200.0
WARMUP_STEP_S = 900.0
WARMUP_STEPS = 4
# Heating only (ArduPilot's): after settling, one ramp at a quarter of the chamber's fastest rate.
HEATING_ONLY_RATE_FRACTION = 0.25
# The candidate designs' rates: the chamber's fastest and these fractions of it.
RATE_FRACTIONS: tuple[float, ...] = (1.0, 0.5, 0.25)


@dataclass(frozen=True)
class Program:
    name: str
    start_c: float
    segments: tuple[SegmentSpec, ...]

    @property
    def duration_s(self) -> float:
        return math.fsum(s.duration_s for s in self.segments)

    @property
    def protocol(self) -> ProtocolConfig:
        return ProtocolConfig("custom", self.start_c, self.segments)

    def corners(self) -> list[tuple[float, float]]:
        """``(time_s, set-point degC)`` at every segment start and end (a step shows as two rows)."""
        rows, clock, current = [(0.0, self.start_c)], 0.0, self.start_c
        for spec in self.segments:
            if spec.end_c != current and spec.label in ("soak", "hold"):
                rows.append((clock, spec.end_c))
            clock += spec.duration_s
            rows.append((clock, spec.end_c))
            current = spec.end_c
        return rows


def ramp_rate(previous_c: float, spec: SegmentSpec) -> float:
    """A ramp's rate in degC/min (0 for a soak or hold)."""
    return 0.0 if spec.label in ("soak", "hold") else abs(spec.end_c - previous_c) / spec.duration_s * 60.0


def _ramp(from_c: float, to_c: float, rate: float) -> SegmentSpec:
    return SegmentSpec("ramp_up" if to_c > from_c else "ramp_down", abs(to_c - from_c) / rate * 60.0, to_c)


def standard(limits: ChamberLimits) -> tuple[Program, ...]:
    """The profiles calibrations use today: the paper's oven, one cycle like the bundled run, a warm-up
    from cold (PX4), heating only (ArduPilot); the last two over the chamber's range."""
    lo, hi = limits.low_c, limits.high_c
    warm: list[SegmentSpec] = []
    for k in range(1, WARMUP_STEPS + 1):
        warm.append(
            SegmentSpec(
                "ramp_up", WARMUP_STEP_S, lo + (hi - lo) * (1 - math.exp(-k * WARMUP_STEP_S / WARMUP_TAU_S))
            )
        )
    heat_rate = limits.max_rate_c_per_min * HEATING_ONLY_RATE_FRACTION
    return (
        Program("paper oven", *PAPER_OVEN),
        Program("single cycle (bundled run)", *BUNDLED_CYCLE),
        Program("warm-up from cold (PX4)", lo, tuple(warm)),
        Program(
            "heating only (ArduPilot)",
            lo,
            (
                SegmentSpec("soak", limits.settling_s, lo),
                _ramp(lo, hi, heat_rate),
                SegmentSpec("hold", limits.settling_s, hi),
            ),
        ),
    )


def _leg(segments: list[SegmentSpec], current: float, to_c: float, rate: float, settle_s: float) -> float:
    segments += [_ramp(current, to_c, rate), SegmentSpec("hold", settle_s, to_c)]
    return to_c


def candidates(limits: ChamberLimits) -> list[Program]:
    """The designs, shortest first, within the chamber's limits: after settling at the cold end, up
    to the hot end and back down (the whole range, or to its middle) at two rates (or one), each
    ramp followed by a settling hold; with the whole range, optionally a third ramp at another rate
    back up to the middle (a reversal inside the range)."""
    lo, hi, settle = limits.low_c, limits.high_c, limits.settling_s
    mid = 0.5 * (lo + hi)
    rates = [limits.max_rate_c_per_min * f for f in RATE_FRACTIONS]
    out: list[Program] = []
    for up, down in product(rates, rates):
        for turn, third in [(mid, None), (lo, None), *((lo, r) for r in rates if r not in (up, down))]:
            segments = [SegmentSpec("soak", settle, lo)]
            current = _leg(segments, lo, hi, up, settle)
            current = _leg(segments, current, turn, down, settle)
            name = f"{lo:g}>{hi:g} at {up:g}, >{turn:g} at {down:g}"
            if third is not None:
                _leg(segments, current, mid, third, settle)
                name += f", >{mid:g} at {third:g}"
            out.append(Program(f"{name} degC/min", lo, tuple(segments)))
    fitting = [p for p in out if p.duration_s <= limits.max_duration_s * (1 + 1e-9)]
    return sorted(fitting, key=lambda p: (p.duration_s, p.name))
