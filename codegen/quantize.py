"""Float specs -> fixed-point models, with every scale, shift and worst-case bound decided offline.

Each C family quantises its own model (its unit's quantiser, codegen/families/, which documents
its formats); this module holds what they share and dispatches :func:`quantise_checkpoint`.

=====================  ===========  ======================================================
quantity               storage      format
=====================  ===========  ======================================================
acceleration in/out    int32        Q4 micro-g: 1 LSB = 1/16 ug (62.5 ng), range +-134 g
temperature in         int32        milli-degC
=====================  ===========  ======================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

from codegen import family
from codegen.family import QuantModel, family_of
from codegen.fixedpoint import INT32_MAX, round_half_away
from codegen.spec import Checkpoint
from trainer import methods as registry
from trainer.errors import UserError

ACCEL_FRAC = 4  # the step API's acceleration unit is 2**-4 ug
ACCEL_PER_MG = 1000 << ACCEL_FRAC
INT64_SAFE = 1 << 62  # every int64 intermediate stays below this (one bit of margin)
TEMP_LIMITS_MDEGC = (-100_000, 200_000)  # the front end clamps temperatures to -100 .. 200 degC
FLAG_TEMP_OUT_OF_RANGE = 1
FLAG_INPUT_CLAMPED = 2
FLAG_SATURATED = 4


@dataclass(frozen=True)
class Limits:
    """Input ranges the front end clamps to (documented edges; clamping sets a flag)."""

    # |raw input| clamp of a module whose network reads it, in LSB (1/16000 of the unit): the
    # limit of the channel's unit (codegen/input_limits.py: --accel-limit-g, --gyro-limit-dps)
    signal_lsb: int
    temp_lo_mdegc: int = TEMP_LIMITS_MDEGC[0]
    temp_hi_mdegc: int = TEMP_LIMITS_MDEGC[1]
    valid_lo_mdegc: int = TEMP_LIMITS_MDEGC[0]  # the model's valid range, for the flag only
    valid_hi_mdegc: int = TEMP_LIMITS_MDEGC[1]
    unit: str = "mg"  # the channel's (mg, dps, pa): one LSB of the step's input and output is 1/16000 of it


def _limits(ckpt: Checkpoint, signal_lsb: int) -> Limits:
    if not 0 < signal_lsb <= INT32_MAX:
        raise ValueError(f"raw-input clamp {signal_lsb} LSB is not in (0, {INT32_MAX}]")
    lo, hi = ckpt.valid_temp_range_c
    clamp_c = [limit / 1000 for limit in TEMP_LIMITS_MDEGC]
    if not clamp_c[0] <= lo <= hi <= clamp_c[1]:
        raise UserError(
            f"checkpoint field 'valid_temp_range_c' {lo:g} .. {hi:g} degC is outside the {clamp_c[0]:g} .. "
            f"{clamp_c[1]:g} degC the module clamps its temperature to, so its out-of-range flag could never "
            f"fire: a model fitted on impossible temperatures; re-fit on a recording without them"
        )
    clip = (-(1 << 31) + 1, INT32_MAX)
    # rounded as the firmware's mdegC reading of the range's ends is (and as the physics clamp is): the
    # hottest training sample (73.96679 degC, read as 73967) is inside, not flagged out of range
    valid_lo = min(max(round_half_away(Fraction(lo) * 1000), clip[0]), clip[1])
    valid_hi = min(max(round_half_away(Fraction(hi) * 1000), clip[0]), clip[1])
    return Limits(
        signal_lsb,
        valid_lo_mdegc=valid_lo,
        valid_hi_mdegc=valid_hi,
        unit=ckpt.unit,
    )


def quantise_checkpoint(ckpt: Checkpoint, *, signal_lsb: int, schedule: str = "step") -> QuantModel:
    """The fixed-point model of a parsed checkpoint (deterministic: same input, same integers);
    ``signal_lsb``: where a model whose network reads its raw input clamps it, in LSB
    (:func:`codegen.input_limits.signal_lsb` of the checkpoint's unit)."""
    limits = _limits(ckpt, signal_lsb)
    model = ckpt.model
    if schedule not in family.schedules():
        raise UserError(f"--schedule must be one of {', '.join(family.schedules())}, got {schedule!r}")
    unit = family_of(model)
    if schedule not in unit.schedules:
        renderers = {m: registry.get(m).renderer for m in registry.names()}
        takers = [m for m, r in renderers.items() if r is not None and schedule in family.get(r).schedules]
        raise UserError(
            f"--schedule {schedule}: method {model.method!r} takes only {', '.join(unit.schedules)}; "
            f"{schedule} is for {', '.join(takers)}"
        )
    return unit.quantise(model, limits, schedule)
