"""The held-out score of a model fitted with ``trainer fit --holdout``, kept in its checkpoint.

A model fitted on part of a run has the rest to be judged on; before, the checkpoint kept no score,
so ``codegen export`` put a model into firmware that ``trainer evaluate --holdout`` would have shown
worse than no compensation. ``fit`` now scores the held-out part as ``trainer report --holdout`` does
(:func:`trainer.scoring.unit_scores.score_unit`: the output over the whole run from its start, the
part cut from it; the validation smoothing; uncompensated beside it), records the figures in
``train_stats.held_out`` and prints them; the sign-off's guard
(:func:`trainer.scoring.verdict.worse_than_uncompensated`) judges them, and ``codegen export``
refuses a model it fails.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from trainer.data.holdout import Holdout, parse_holdout
from trainer.data.recording import Recording
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.scoring.unit_scores import PartScores, score_unit
from trainer.scoring.verdict import Figures, Guard, worse_than_uncompensated
from trainer.train_stats import HELD_OUT_FIGURES, TrainStats


def _number(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def held_out_record(
    model: Any, whole: Recording, holdout: Holdout, trained_range_c: tuple[float, float]
) -> dict[str, Any]:
    """The figures of ``model`` (fitted on what ``holdout`` leaves of ``whole``) on the part it held
    out, as plain values for ``train_stats.held_out``."""
    rec = whole.without_truth()
    compensated = np.asarray(model.compensate(rec), dtype=np.float64)
    part = score_unit(rec, compensated, PAPER_RUN_SMOOTHING_S, trained_range_c, holdout).held_out
    assert part is not None
    return record_of(holdout, part_figures(part))


def part_figures(part: PartScores) -> tuple[float, ...]:
    """A part's figures in the order of :data:`~trainer.train_stats.HELD_OUT_FIGURES` (NaN: not measured)."""
    in_range = (part.model_in_range, part.uncompensated_in_range)
    return (
        part.model.rms_mg,
        part.uncompensated.rms_mg,
        *(math.nan if x is None else x.rms_mg for x in in_range),
        part.noise_floor_mg,
    )


def record_of(holdout: Holdout, figures: Sequence[float]) -> dict[str, Any]:
    """``train_stats.held_out``: the split and the figures (a NaN, not measured, is stored as null)."""
    return {
        "holdout": holdout.spec,
        "smoothing_s": PAPER_RUN_SMOOTHING_S,
        **{key: _number(value) for key, value in zip(HELD_OUT_FIGURES, figures, strict=True)},
    }


def _figure(record: dict[str, Any], key: str) -> float:
    value = record.get(key)
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else math.nan


def held_out_figures(record: dict[str, Any], unit: str) -> Figures:
    """The recorded figures as the sign-off's guard reads them (NaN where not measured)."""
    model, raw, model_in_range, raw_in_range, floor = (_figure(record, key) for key in HELD_OUT_FIGURES)
    basis = f"held-out part (--holdout {record.get('holdout')} of the training run, scored by trainer fit)"
    return Figures(basis, model, raw, model_in_range, raw_in_range, floor, unit)


def held_out_guard(stats: TrainStats, subject: str, unit: str) -> Guard | None:
    """The sign-off's guard on the recorded held-out figures; None for a model fitted on a whole run."""
    if stats.held_out is None:
        return None
    return worse_than_uncompensated(subject, held_out_figures(stats.held_out, unit))


def held_out_line(stats: TrainStats, subject: str, unit: str) -> str | None:
    """One line for ``trainer fit --holdout``: the guard's comparison, and what export will do."""
    guard = held_out_guard(stats, subject, unit)
    if guard is None:
        return None
    if guard.ok:
        return f"{subject}: {guard.detail}"
    return f"warning: {subject}: {guard.detail}; codegen export refuses it (it must not reach firmware)"


def with_held_out_score(model: Any, stats: TrainStats, whole: Recording, spec: str | None) -> TrainStats:
    """``stats`` with the model's figures on the part ``--holdout spec`` held out of ``whole`` (the same
    channel's whole run), unchanged without a hold-out."""
    if spec is None:
        return stats
    return replace(stats, held_out=held_out_record(model, whole, parse_holdout(spec), stats.temp_range_c))
