"""The reference temperature and the offset policy of every temperature-driven compensator.

A thermal compensator must remove the *temperature-dependent* part of the bias, not the static
offset: the offset (and gravity, on a static fixture) belongs to the separate accelerometer
calibration, exactly as in flight stacks (PX4's ``TC_A*_X0`` polynomial is about ``TREF``; its
six-position calibration owns the offset). So by default a compensator whose drift estimate is a
function of the temperature (families ``memoryless`` and ``temperature-driven`` of
:mod:`trainer.methods`) is shifted after fitting so that its drift estimate is zero at the
**reference temperature** ``T_ref``:

- ``T_ref`` is the mid-point of the training temperature range, ``(T_min + T_max) / 2`` (PX4's
  ``TREF``), unless the user gives one (``--tref``, inside the training range);
- ``relative`` (the default): the compensator removes ``d(T) - d(T_ref)``; the constant
  ``d(T_ref)`` stays in the output;
- ``absolute``: the fitted constant is removed too (the paper's static test, whose drift has a zero
  reference); refused when it exceeds :data:`OFFSET_LIMIT_MG` (gravity or a static offset);
- ``absolute-unbounded``: the same without the limit (for a user who really wants it).

Recursive methods learn from the past output and remove any sustained acceleration (a tilt, a
change of attitude, gravity) along with the drift; they have no reference temperature, and
:data:`RECURSIVE_NOTE` says so wherever they are exported.

This module is a leaf (no project imports but errors): the compensator interface and the fitting
code import it. :func:`trainer.fitting.apply_offset_policy` applies the policy to a fitted model.

Scoring follows the same reference: on simulated data a relative method's drift left is measured
against ``true_drift - true_drift(T_ref)`` (:func:`value_at_temperature`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from trainer.errors import UserError

OffsetMode = Literal["relative", "absolute", "absolute-unbounded"]
OFFSET_MODES: tuple[OffsetMode, ...] = ("relative", "absolute", "absolute-unbounded")
OFFSET_OPTION = "--offset"  # the one option that chooses the mode (trainer/options/offset.py)
TREF_OPTION = "--tref"
OFFSET_LIMIT_MG = 100.0  # a larger constant is gravity or a static offset, not thermal drift
RECURSIVE_NOTE = (
    "recursive method: it learns from the past output and removes any sustained acceleration "
    "(a tilt, a change of attitude, gravity) along with the drift; use a temperature-driven method "
    "where the true input can be constant for long"
)
# the same warning in the words of each channel's sustained input (RECURSIVE_NOTE is the accelerometer's)
_SUSTAINED_INPUT = {
    "dps": "any sustained rotation rate (a steady turn, the Earth's rotation)",
    "pa": "any sustained pressure (an altitude held, the weather)",
}


def recursive_note(unit: str = "mg") -> str:
    """:data:`RECURSIVE_NOTE` for a channel of ``unit`` (mg, dps, pa: what the method removes there)."""
    sustained = _SUSTAINED_INPUT.get(unit)
    if sustained is None:
        return RECURSIVE_NOTE
    return RECURSIVE_NOTE.replace(
        "any sustained acceleration (a tilt, a change of attitude, gravity)", sustained
    )


def reference_temperature(temp_c: np.ndarray, t_ref_c: float | None = None) -> float:
    """``T_ref``: the user's value when given (inside the range of ``temp_c``), else the range mid-point."""
    t_min, t_max = float(np.min(temp_c)), float(np.max(temp_c))
    if t_ref_c is None:
        return 0.5 * (t_min + t_max)
    if not (np.isfinite(t_ref_c) and t_min <= t_ref_c <= t_max):
        raise UserError(
            f"{TREF_OPTION} {t_ref_c:g} degC lies outside the training temperature range "
            f"{t_min:.2f} .. {t_max:.2f} degC"
        )
    return float(t_ref_c)


@dataclass(frozen=True)
class OffsetPolicy:
    """What the user asked for: the mode and, optionally, ``T_ref``."""

    mode: OffsetMode = "relative"
    t_ref_c: float | None = None

    def __post_init__(self) -> None:
        if self.mode not in OFFSET_MODES:
            raise UserError(f"{OFFSET_OPTION} {self.mode!r}: choose one of {', '.join(OFFSET_MODES)}")


@dataclass(frozen=True)
class OffsetRecord:
    """What a fitted temperature-driven compensator does with the constant (kept in ``model.pt``).

    ``drift_at_t_ref_mg`` is the fitted model's drift at ``T_ref`` before the policy: the static
    offset (gravity included on a static fixture) plus the drift at ``T_ref``.
    """

    mode: OffsetMode
    t_ref_c: float
    drift_at_t_ref_mg: float

    @property
    def relative(self) -> bool:
        return self.mode == "relative"

    @property
    def removed_mg(self) -> float:
        """The constant the compensator removes (0 when relative)."""
        return 0.0 if self.relative else self.drift_at_t_ref_mg

    def to_dict(self) -> dict[str, Any]:
        return {"mode": self.mode, "t_ref_c": self.t_ref_c, "drift_at_t_ref_mg": self.drift_at_t_ref_mg}

    @classmethod
    def from_dict(cls, data: Any) -> OffsetRecord:
        """From :meth:`to_dict`'s output; ValueError when malformed."""
        if not isinstance(data, dict) or data.get("mode") not in OFFSET_MODES:
            raise ValueError(f"offset record {data!r}: 'mode' must be one of {OFFSET_MODES}")
        t_ref, constant = float(data["t_ref_c"]), float(data["drift_at_t_ref_mg"])
        if not (np.isfinite(t_ref) and np.isfinite(constant)):
            raise ValueError("offset record: 't_ref_c' and 'drift_at_t_ref_mg' must be finite")
        return cls(data["mode"], t_ref, constant)

    def describe(self) -> str:
        """The one line ``fit``, ``compare`` and ``codegen export`` print."""
        if self.relative and self.drift_at_t_ref_mg == 0.0:  # the identity (auto's none): no level to keep
            return (
                f"offset: drift relative to T_ref {self.t_ref_c:.2f} degC, constant removed 0 mg "
                "(the model has no drift: the channel's level stays in the output as it is)"
            )
        if self.relative:
            return (
                f"offset: drift relative to T_ref {self.t_ref_c:.2f} degC, constant removed 0 mg "
                f"(the {self.drift_at_t_ref_mg:.4g} mg at T_ref stays in the output for the "
                f"accelerometer calibration; {OFFSET_OPTION} absolute removes it)"
            )
        return (
            f"offset: {self.mode}, constant removed {self.removed_mg:.4g} mg "
            f"(the model's drift at T_ref {self.t_ref_c:.2f} degC)"
        )


def check_constant(record: OffsetRecord, what: str) -> None:
    """Refuse an absolute constant beyond :data:`OFFSET_LIMIT_MG` unless the mode is unbounded."""
    if record.mode == "absolute" and abs(record.removed_mg) > OFFSET_LIMIT_MG:
        raise UserError(
            f"{what}: would remove a constant of {record.removed_mg:.4g} mg at T_ref "
            f"{record.t_ref_c:.2f} degC (above {OFFSET_LIMIT_MG:g} mg: gravity or a static offset, which "
            f"the accelerometer calibration owns); fit with {OFFSET_OPTION} relative (the default) or "
            f"{OFFSET_OPTION} absolute-unbounded"
        )


def value_at_temperature(temp_c: np.ndarray, values: np.ndarray, t_ref_c: float) -> float:
    """``values`` at temperature ``t_ref_c``: a least-squares line through the samples nearest to it.

    Used for the true drift's value at ``T_ref`` (relative scoring). The band around ``T_ref``
    starts at +-0.5 degC and doubles until it holds 20 samples of at least two temperatures, so
    heating and cooling branches are averaged where both pass; a ``T_ref`` outside the recording's
    range is reached by the line through the nearest samples.
    """
    temp = np.asarray(temp_c, dtype=np.float64)
    vals = np.asarray(values, dtype=np.float64)
    distance = np.abs(temp - t_ref_c)
    band = max(0.5, float(np.min(distance)))
    while True:
        near = distance <= band
        if (np.count_nonzero(near) >= 20 and np.ptp(temp[near]) > 0) or band > 1e3:
            break
        band *= 2.0
    if not np.ptp(temp[near]) > 0:
        return float(np.mean(vals[near]))
    slope, intercept = np.polynomial.polynomial.polyfit(temp[near], vals[near], 1)[::-1]
    return float(slope * t_ref_c + intercept)
