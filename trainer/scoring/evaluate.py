"""Score compensators on a validation recording: the paper's Table 1 plus honest drift metrics.

The paper smooths the validation data over 0.5 s before its Allan analysis; the same trailing
moving average is applied here to the raw output and to every compensated output alike, so the
columns stay comparable. The Allan improvement rewards any high-pass operation, so when the
recording carries ground truth the residual drift RMS against ``true_drift_mg`` is reported too:
``drift_estimate = accel - compensated`` and ``residual = true_drift - drift_estimate``. A method
that models the drift relative to a reference temperature (:mod:`trainer.reference`) is scored
against ``true_drift - true_drift(T_ref)``. Without ground truth (a real recording) the drift left
is the compensated output's deviation from a constant (:mod:`trainer.scoring.static`), so there
is always a headline figure.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trainer.data.recording import Recording
from trainer.data.smoothing import moving_average, window_samples
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.errors import UserError
from trainer.reference import value_at_temperature
from trainer.scoring.allan import AllanCurve, AllanTable, allan_table, default_taus
from trainer.scoring.static import (
    COOLING,
    HEATING,
    DriftLeft,
    noise_floor_mg,
    static_drift_left,
    summarise,
    thermal_branch,
)

PAPER_VALIDATION_SMOOTHING_S = PAPER_RUN_SMOOTHING_S  # the paper's 0.5 s validation smoothing
# A moving average of width w distorts the Allan deviation for tau up to a few w (the hump in
# Figure 13 below 1 s); coefficients are read only from tau >= this many windows.
MIN_TAU_IN_SMOOTHING_WINDOWS = 4.0


@dataclass(frozen=True)
class DriftScore:
    """How much real drift a method left behind (needs ``true_drift_mg``).

    ``t_ref_c``: the true drift was taken relative to its value there (None: absolute).
    """

    residual_rms_mg: float
    residual_max_abs_mg: float
    raw_drift_rms_mg: float
    t_ref_c: float | None = None
    left: DriftLeft | None = None  # the same residual per heating/cooling branch


@dataclass(frozen=True)
class Evaluation:
    """Everything ``trainer evaluate`` prints and plots."""

    table: AllanTable
    curves: Mapping[str, AllanCurve]
    smoothed: dict[str, np.ndarray]
    drift: dict[str, DriftScore]
    out_of_range_fraction: dict[str, float]
    smoothing_s: float
    static: dict[str, DriftLeft]  # deviation from a constant, "raw" included
    noise_floor_mg: float  # white-noise RMS of the raw output after the smoothing
    branch_fractions: tuple[float, float]  # share of heating and of cooling samples
    raw_drift: DriftScore | None = None  # the uncompensated output against the truth (common T_ref)
    # static deviation over the samples inside the training temperature range (range-checked methods
    # and "raw"; empty when every sample is inside): extrapolation is scored apart from compensation
    static_in_range: dict[str, DriftLeft] = field(default_factory=dict)

    def drift_left(self, name: str) -> DriftLeft | None:
        """The headline drift left of ``name``: against ground truth when there is one, else static."""
        if self.drift:
            score = self.raw_drift if name == "raw" else self.drift.get(name)
            return score.left if score is not None else None
        return self.static.get(name)

    @property
    def basis(self) -> str:
        """What the headline drift left is measured against."""
        return "true drift" if self.drift else "deviation from a constant (static recording)"


def smooth_for_scoring(x: np.ndarray, rate_hz: float, smoothing_s: float) -> np.ndarray:
    """The paper's validation smoothing (trailing moving average); 0 disables it."""
    if smoothing_s <= 0:
        return np.asarray(x, dtype=np.float64)
    return moving_average(x, window_samples(smoothing_s, rate_hz), mode="trailing")


def truth_reference_c(model: Any) -> float | None:
    """The ``T_ref`` a model's output is relative to (its offset policy), against which the simulator's
    true drift is scored; None for a model that removes its whole drift. ``trainer evaluate`` and the
    fleet score with it, so that their ``residual vs truth`` is one figure."""
    offset = getattr(model, "offset", None)
    return float(offset.t_ref_c) if offset is not None and offset.relative else None


def drift_score(
    rec: Recording,
    compensated: np.ndarray,
    t_ref_c: float | None = None,
    branch: np.ndarray | None = None,
) -> DriftScore | None:
    """Residual drift against ground truth (relative to ``t_ref_c`` when given), or None without it."""
    true_drift = rec.truth("drift_mg")
    if true_drift is None:
        return None
    if t_ref_c is not None:
        true_drift = true_drift - value_at_temperature(rec.temp_c, true_drift, t_ref_c)
    residual = true_drift - (rec.accel_mg - compensated)
    if branch is None:
        branch = thermal_branch(rec.temp_c, rec.sample_rate_hz)
    return DriftScore(
        residual_rms_mg=float(np.sqrt(np.mean(residual**2))),
        residual_max_abs_mg=float(np.max(np.abs(residual))),
        raw_drift_rms_mg=float(np.sqrt(np.mean(true_drift**2))),
        t_ref_c=t_ref_c,
        left=summarise(residual, branch),
    )


def scoring_taus(rec: Recording, smoothing_s: float) -> np.ndarray:
    """The Allan analysis' averaging times (s) for ``rec``; a recording too short to give one is the
    user's (a short or truncated file), so it is a one-line UserError, not a traceback."""
    rate = rec.sample_rate_hz
    try:
        taus = default_taus(len(rec), rate)
    except ValueError:  # not one averaging time up to the cap
        taus = np.empty(0)
    taus = taus[taus >= MIN_TAU_IN_SMOOTHING_WINDOWS * smoothing_s]
    if taus.size == 0:
        raise UserError(
            f"{rec.source}: {len(rec)} rows at {rate:.6g} Hz are too short to score: the Allan analysis "
            f"needs averaging times from {MIN_TAU_IN_SMOOTHING_WINDOWS * smoothing_s:g} s (after the "
            f"{smoothing_s:g} s smoothing) up to a tenth of the run; score a longer recording"
        )
    return taus


def evaluate(
    rec: Recording,
    compensated: dict[str, np.ndarray],
    *,
    out_of_range: dict[str, np.ndarray] | None = None,
    smoothing_s: float = PAPER_VALIDATION_SMOOTHING_S,
    references: dict[str, float] | None = None,
) -> Evaluation:
    """Score each compensated output of ``rec`` (name -> 200 Hz compensated signal in mg).

    ``references``: name -> ``T_ref`` of the methods that model the drift relative to it.
    """
    rate = rec.sample_rate_hz
    taus = scoring_taus(rec, smoothing_s)
    smoothed = {"raw": smooth_for_scoring(rec.accel_mg, rate, smoothing_s)}
    smoothed.update({name: smooth_for_scoring(x, rate, smoothing_s) for name, x in compensated.items()})
    table = allan_table(smoothed["raw"], {k: v for k, v in smoothed.items() if k != "raw"}, rate, taus=taus)
    branch = thermal_branch(rec.temp_c, rate)
    refs = references or {}
    drift = {
        name: s
        for name, x in compensated.items()
        if (s := drift_score(rec, x, refs.get(name), branch)) is not None
    }
    fractions = {name: float(np.mean(mask)) for name, mask in (out_of_range or {}).items()}
    static = {name: static_drift_left(x, branch) for name, x in smoothed.items()}
    window = window_samples(smoothing_s, rate) if smoothing_s > 0 else 1
    floor = noise_floor_mg(rec.accel_mg, window)
    shares = (float(np.mean(branch == HEATING)), float(np.mean(branch == COOLING)))
    # Fewer in-range samples than one smoothing window are one value: its deviation from its own mean
    # would read 0 (a held-out part that touches the training range at one sample), not a score.
    least = max(2, window)
    partly_outside = {
        name: mask
        for name, mask in (out_of_range or {}).items()
        if mask.any() and int(np.count_nonzero(~mask)) >= least
    }
    in_range = {
        name: static_drift_left(smoothed[name][~mask], branch[~mask]) for name, mask in partly_outside.items()
    }
    if partly_outside:
        mask = next(iter(partly_outside.values()))
        in_range["raw"] = static_drift_left(smoothed["raw"][~mask], branch[~mask])
    common = set(refs.values())
    raw_drift = drift_score(rec, rec.accel_mg, common.pop() if len(common) == 1 else None, branch)
    return Evaluation(
        table,
        table.curves,
        smoothed,
        drift,
        fractions,
        smoothing_s,
        static,
        floor,
        shares,
        raw_drift,
        in_range,
    )


@dataclass(frozen=True)
class InputSurvival:
    """How much of a true input signal a compensator keeps (needs ``true_accel_mg``).

    ``gain`` is the least-squares gain of the compensated output on the true input (1 = kept
    whole, 0 = destroyed); ``error_rms_mg`` is the RMS of compensated minus true input minus
    sensor noise, i.e. everything the compensator got wrong (drift left plus signal removed).
    """

    gain: float
    error_rms_mg: float
    input_rms_mg: float


def input_survival(rec: Recording, compensated: np.ndarray) -> InputSurvival | None:
    true_input = rec.truth("accel_mg")
    if true_input is None or not np.ptp(true_input) > 0:
        return None
    centred = true_input - true_input.mean()
    gain = float(np.dot(compensated - compensated.mean(), centred) / np.dot(centred, centred))
    noise = rec.truth("noise_mg")
    error = compensated - true_input - (noise if noise is not None else 0.0)
    return InputSurvival(gain, float(np.sqrt(np.mean(error**2))), float(np.sqrt(np.mean(centred**2))))
