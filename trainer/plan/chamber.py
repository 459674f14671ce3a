"""The check that a program respects the chamber's limits, and the validation profile."""

from __future__ import annotations

from trainer.physics.profiles import REALISTIC_VALID, SegmentSpec
from trainer.plan.limits import ChamberLimits
from trainer.plan.programs import Program, ramp_rate

RATE_SLACK = 1e-9  # relative: a ramp built at exactly the maximum rate passes


def violations(program: Program, limits: ChamberLimits) -> list[str]:
    """Every way ``program`` leaves the chamber's limits (empty: it respects them)."""
    found = []
    if program.duration_s > limits.max_duration_s * (1 + RATE_SLACK):
        found.append(f"lasts {program.duration_s / 3600:.2f} h > {limits.max_duration_s / 3600:g} h")
    previous = program.start_c
    for index, spec in enumerate(program.segments, 1):
        where = f"segment {index} ({spec.label})"
        if not limits.low_c <= spec.end_c <= limits.high_c:
            found.append(f"{where} set-point {spec.end_c:g} degC outside {limits.low_c:g}..{limits.high_c:g}")
        if spec.label in ("soak", "hold"):
            if spec.end_c != previous:
                found.append(f"{where} steps the set-point from {previous:g} to {spec.end_c:g} degC")
            if spec.duration_s < limits.settling_s:
                found.append(
                    f"{where} {spec.duration_s:g} s is shorter than the settling {limits.settling_s:g} s"
                )
        elif ramp_rate(previous, spec) > limits.max_rate_c_per_min * (1 + RATE_SLACK):
            found.append(f"{where} {ramp_rate(previous, spec):g} degC/min > {limits.max_rate_c_per_min:g}")
        previous = spec.end_c
    if not limits.low_c <= program.start_c <= limits.high_c:
        found.append(f"starts at {program.start_c:g} degC outside {limits.low_c:g}..{limits.high_c:g}")
    return found


def validation_program(limits: ChamberLimits) -> Program:
    """The realistic validation cycle (starting hot, other rates, the range in another order) mapped
    onto the chamber's range at its own rates (capped at the chamber's): independent of any design."""
    start, specs = REALISTIC_VALID
    lo, hi = min(s.end_c for s in specs), max(s.end_c for s in specs)

    def mapped(temp_c: float) -> float:
        return limits.low_c + (temp_c - lo) / (hi - lo) * (limits.high_c - limits.low_c)

    out: list[SegmentSpec] = []
    previous = start
    for spec in specs:
        if spec.label in ("soak", "hold"):
            out.append(SegmentSpec(spec.label, spec.duration_s, mapped(spec.end_c)))
        else:
            rate = min(ramp_rate(previous, spec), limits.max_rate_c_per_min)
            span = abs(mapped(spec.end_c) - mapped(previous))
            out.append(SegmentSpec(spec.label, span / rate * 60.0, mapped(spec.end_c)))
        previous = spec.end_c
    return Program("realistic validation", mapped(start), tuple(out))
