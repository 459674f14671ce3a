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
from dataclasses import replace
from typing import Any

import numpy as np

from trainer.data.holdout import parse_holdout
from trainer.data.recording import Recording
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.scoring.unit_scores import score_unit
from trainer.scoring.verdict import Figures, Guard, worse_than_uncompensated
from trainer.train_stats import TrainStats


def _number(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def held_out_record(
    model: Any, whole: Recording, spec: str, trained_range_c: tuple[float, float]
) -> dict[str, Any]:
    """The figures of ``model`` (fitted on what ``--holdout spec`` leaves of ``whole``) on the part
    it held out, as plain values for ``train_stats.held_out``."""
    rec = whole.without_truth()
    compensated = np.asarray(model.compensate(rec), dtype=np.float64)
    part = score_unit(rec, compensated, PAPER_RUN_SMOOTHING_S, trained_range_c, parse_holdout(spec)).held_out
    assert part is not None
    return {
        "holdout": spec,
        "smoothing_s": PAPER_RUN_SMOOTHING_S,
        "model_rms": _number(part.model.rms_mg),
        "uncompensated_rms": _number(part.uncompensated.rms_mg),
        "model_in_range_rms": None if part.model_in_range is None else _number(part.model_in_range.rms_mg),
        "uncompensated_in_range_rms": None
        if part.uncompensated_in_range is None
        else _number(part.uncompensated_in_range.rms_mg),
        "noise_floor": _number(part.noise_floor_mg),
    }


def _figure(record: dict[str, Any], key: str) -> float:
    value = record.get(key)
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else math.nan


def held_out_guard(stats: TrainStats, subject: str, unit: str) -> Guard | None:
    """The sign-off's guard on the recorded held-out figures; None for a model fitted on a whole run."""
    record = stats.held_out
    if record is None:
        return None
    figures = Figures(
        f"held-out part (--holdout {record.get('holdout')})",
        _figure(record, "model_rms"),
        _figure(record, "uncompensated_rms"),
        _figure(record, "model_in_range_rms"),
        _figure(record, "uncompensated_in_range_rms"),
        _figure(record, "noise_floor"),
        unit,
    )
    return worse_than_uncompensated(subject, figures)


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
    return replace(stats, held_out=held_out_record(model, whole, spec, stats.temp_range_c))
