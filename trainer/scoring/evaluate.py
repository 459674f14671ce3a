"""Score compensators on a validation recording: the paper's Table 1 plus honest drift metrics.

The paper smooths the validation data over 0.5 s before its Allan analysis; the same trailing
moving average is applied here to the raw output and to every compensated output alike, so the
columns stay comparable. The Allan improvement rewards any high-pass operation, so when the
recording carries ground truth the residual drift RMS against ``true_drift_mg`` is reported too:
``drift_estimate = accel - compensated`` and ``residual = true_drift - drift_estimate``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from trainer.data.recording import Recording
from trainer.data.smoothing import moving_average, window_samples
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.scoring.allan import AllanCurve, AllanTable, allan_table, default_taus

PAPER_VALIDATION_SMOOTHING_S = PAPER_RUN_SMOOTHING_S  # the paper's 0.5 s validation smoothing
# A moving average of width w distorts the Allan deviation for tau up to a few w (the hump in
# Figure 13 below 1 s); coefficients are read only from tau >= this many windows.
MIN_TAU_IN_SMOOTHING_WINDOWS = 4.0


@dataclass(frozen=True)
class DriftScore:
    """How much real drift a method left behind (needs ``true_drift_mg``)."""

    residual_rms_mg: float
    residual_max_abs_mg: float
    raw_drift_rms_mg: float


@dataclass(frozen=True)
class Evaluation:
    """Everything ``trainer evaluate`` prints and plots."""

    table: AllanTable
    curves: Mapping[str, AllanCurve]
    smoothed: dict[str, np.ndarray]
    drift: dict[str, DriftScore]
    out_of_range_fraction: dict[str, float]
    smoothing_s: float


def smooth_for_scoring(x: np.ndarray, rate_hz: float, smoothing_s: float) -> np.ndarray:
    """The paper's validation smoothing (trailing moving average); 0 disables it."""
    if smoothing_s <= 0:
        return np.asarray(x, dtype=np.float64)
    return moving_average(x, window_samples(smoothing_s, rate_hz), mode="trailing")


def drift_score(rec: Recording, compensated: np.ndarray) -> DriftScore | None:
    """Residual drift against ground truth, or None when the recording has none."""
    true_drift = rec.truth("drift_mg")
    if true_drift is None:
        return None
    residual = true_drift - (rec.accel_mg - compensated)
    return DriftScore(
        residual_rms_mg=float(np.sqrt(np.mean(residual**2))),
        residual_max_abs_mg=float(np.max(np.abs(residual))),
        raw_drift_rms_mg=float(np.sqrt(np.mean(true_drift**2))),
    )


def evaluate(
    rec: Recording,
    compensated: dict[str, np.ndarray],
    *,
    out_of_range: dict[str, np.ndarray] | None = None,
    smoothing_s: float = PAPER_VALIDATION_SMOOTHING_S,
) -> Evaluation:
    """Score each compensated output of ``rec`` (name -> 200 Hz compensated signal in mg)."""
    rate = rec.sample_rate_hz
    smoothed = {"raw": smooth_for_scoring(rec.accel_mg, rate, smoothing_s)}
    smoothed.update({name: smooth_for_scoring(x, rate, smoothing_s) for name, x in compensated.items()})
    taus = default_taus(len(rec), rate)
    taus = taus[taus >= MIN_TAU_IN_SMOOTHING_WINDOWS * smoothing_s]
    table = allan_table(smoothed["raw"], {k: v for k, v in smoothed.items() if k != "raw"}, rate, taus=taus)
    drift = {name: s for name, x in compensated.items() if (s := drift_score(rec, x)) is not None}
    fractions = {name: float(np.mean(mask)) for name, mask in (out_of_range or {}).items()}
    return Evaluation(table, table.curves, smoothed, drift, fractions, smoothing_s)


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
