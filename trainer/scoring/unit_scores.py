"""The drift left a unit is signed off on: one function for ``trainer report`` and ``trainer fleet``.

Both score a model's output on a static recording the way ``trainer compare`` and ``trainer
evaluate`` do (:func:`trainer.scoring.static.static_drift_left` after the validation smoothing,
branches from the part's own temperature rate), over the whole recording and, with a hold-out
(:mod:`trainer.data.holdout`), over the held-out part; each next to the **uncompensated** output
scored the same way, so that a compensator that makes a channel worse is visible, and each also
over the samples inside the trained temperature range when some lie outside it (extrapolation is
scored apart from compensation, as ``evaluate`` does). A held-out end part is cut from the output
over the whole run, so a model's state has run through what precedes it (firmware running since
power-on), as ``compare --holdout`` does.

The figures are in the scored channel's unit (the ``_mg`` names are the one-channel code's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trainer.data.holdout import Holdout, split
from trainer.data.recording import Recording
from trainer.data.smoothing import window_samples
from trainer.scoring.evaluate import smooth_for_scoring
from trainer.scoring.static import DriftLeft, noise_floor_mg, static_drift_left, thermal_branch


@dataclass(frozen=True)
class PartScores:
    """Drift left of the model and of the uncompensated output over one part of a recording."""

    model: DriftLeft
    uncompensated: DriftLeft
    # the same over the samples inside the trained range; None when all (or none) of them are inside
    model_in_range: DriftLeft | None
    uncompensated_in_range: DriftLeft | None
    noise_floor_mg: float  # white-noise RMS of the raw output after the smoothing (no model removes it)


@dataclass(frozen=True)
class UnitScores:
    """The whole recording's scores and, with a hold-out, the held-out part's."""

    whole: PartScores
    held_out: PartScores | None = None

    @property
    def headline(self) -> PartScores:
        """What a unit is judged on: the held-out part when there is one (else the whole, in-sample)."""
        return self.held_out if self.held_out is not None else self.whole


def score_part(
    rec: Recording, compensated: np.ndarray, smoothing_s: float, trained_range_c: tuple[float, float]
) -> PartScores:
    """Model and uncompensated drift left of ``rec`` (``compensated``: the model's output on it)."""
    rate = rec.sample_rate_hz
    branch = thermal_branch(rec.temp_c, rate)
    model = smooth_for_scoring(np.asarray(compensated, dtype=np.float64), rate, smoothing_s)
    raw = smooth_for_scoring(np.asarray(rec.accel_mg, dtype=np.float64), rate, smoothing_s)
    lo, hi = trained_range_c
    inside = (rec.temp_c >= lo) & (rec.temp_c <= hi)
    partial = bool(inside.any() and not inside.all())
    window = window_samples(smoothing_s, rate) if smoothing_s > 0 else 1
    return PartScores(
        static_drift_left(model, branch),
        static_drift_left(raw, branch),
        static_drift_left(model[inside], branch[inside]) if partial else None,
        static_drift_left(raw[inside], branch[inside]) if partial else None,
        noise_floor_mg(rec.accel_mg, window),
    )


def coverage(scored_range_c: tuple[float, float], trained_range_c: tuple[float, float]) -> float:
    """Share of the scored temperature span inside the trained range (1: all of it; a single scored
    temperature counts 1 inside the range, 0 outside). Outside it a model extrapolates or holds."""
    lo, hi = scored_range_c
    t_lo, t_hi = trained_range_c
    if hi <= lo:
        return 1.0 if t_lo <= lo <= t_hi else 0.0
    return max(0.0, min(hi, t_hi) - max(lo, t_lo)) / (hi - lo)


def held_out_rows(rec: Recording, holdout: Holdout) -> tuple[Recording, slice]:
    """The held-out part of ``rec`` and its rows in ``rec`` (the split of ``compare --holdout``)."""
    _, held = split(rec, holdout)
    rows = slice(len(rec) - len(held), len(rec)) if holdout.side == "last" else slice(0, len(held))
    return held, rows


def score_unit(
    rec: Recording,
    compensated: np.ndarray,
    smoothing_s: float,
    trained_range_c: tuple[float, float],
    holdout: Holdout | None = None,
) -> UnitScores:
    """Scores of a model's output over the whole of ``rec`` (computed in one run from its start) and,
    with ``holdout``, over the held-out part cut from that output."""
    whole = score_part(rec, compensated, smoothing_s, trained_range_c)
    if holdout is None:
        return UnitScores(whole)
    held, rows = held_out_rows(rec, holdout)
    return UnitScores(whole, score_part(held, compensated[rows], smoothing_s, trained_range_c))
