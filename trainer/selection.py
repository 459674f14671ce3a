"""``--method auto``: per channel, the compensator that cross-validation says leaves the least drift.

The candidates (:data:`CANDIDATES`, declared here once): no compensation, polynomials of order 1
to 3 in temperature (the flight stacks' cubic and the lower orders that do not over-fit a short
range), PLA and the physics compensator, with its automatic structure, with the branch offset, and
with the branch offset fitted by least squares and started, at power-on, on the branch a sensor
brought from room temperature is on (``physics-branch-room``), and with that offset as a sum of play
operators of widths an octave apart, a loop that widens after a larger excursion
(``physics-branches``, :mod:`trainer.greybox.play_sum`). Each is cross-validated over the run's thermal segments (:mod:`trainer.scoring.crossval`). The rule
(:func:`choose`) judges what a user meets, one held-out segment at a time:

- **A whole cycle** (at least :data:`FULL_CYCLE_SEGMENTS` thermal segments, heating and cooling
  among them, so that a fold trains on more than the one branch it does not hold out): per
  candidate, its worst ratio, over every held-out segment warm and cold, to the better of (cubic,
  no compensation) on that segment; of the candidates whose worst ratio is within
  :data:`TOLERANCE` of the smallest, the one that leaves the least drift pooled over the held-out
  segments (the simplest that leaves at most :data:`POOLED_GAIN` more). A model that wins on
  average but loses badly on one segment is not chosen; nor is the cubic over a model as safe
  that leaves far less (on a run with dwells every candidate ties the cubic on a dwell, so the
  worst ratio alone would always keep to it: the realistic experiment's gyroscope, physics 0.013
  against 0.079 deg/s cross-validated).
- **Less than a cycle** (a run that does not reverse, or one heating and one cooling): each fold trains on one branch
  and extrapolates to the other, which separates the shapes by the noise of one fold (on the
  bundled real run, `bench/bench_real_splits.py`: such choices lost to the cubic held out at most
  of the splits where they differed from it). The choice is then between the flight stacks' cubic
  and no compensation, and the reason says so; the other candidates are not cross-validated.
- Never one that leaves more than no compensation, pooled over the held-out segments or over their
  samples inside the training range (:func:`leaves_more_than_none`, what the sign-off's guard
  reads): when the rule's only such choice is no compensation, it is ``none``, which exports as the
  identity (C) or a disabled entry (flight-stack parameters).

What is fitted and saved is the chosen candidate, trained on the whole run; the checkpoint's
``train_stats.selection`` keeps the table that chose it (:func:`selection_record`). That fit is not
one cross-validation scored (the physics finder can give the whole run another structure than its
folds), so it is checked on its own run: one that leaves more than no compensation on a segment of
it is refused and the rule chooses again without it (:func:`ship`, :func:`own_run_failure`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from trainer import methods
from trainer.data.recording import Recording
from trainer.fleet.cluster import TaskMap
from trainer.physics.catalogue.base import T_REF_C
from trainer.physics.catalogue.hysteresis_offset import DEFINITION as BRANCH_OFFSET
from trainer.reference import OffsetPolicy
from trainer.scoring.crossval import (
    LABELS,
    UNCOMPENSATED,
    CrossValidation,
    Segment,
    cross_validate,
    folds_of,
    own_run_figures,
    segment_lines,
    table_lines,
)
from trainer.scoring.static import COOLING, HEATING
from trainer.scoring.verdict import SegmentFigures
from trainer.train_stats import TrainStats

AUTO = "auto"  # the selector's name on the command line (trainer fit --method auto)
NONE = "none"  # the candidate "no compensation" (a polynomial of order 0: zero drift)
TOLERANCE = 0.02  # a candidate within 2 % of the best counts as as good (the simpler one wins)
# Of candidates as safe as each other, a more complex one must leave this much less pooled: three
# held-out segments separate two by a few per cent by chance (the bundled run's gyro x, trained on its
# last 80 %: poly1 4 % below none pooled, twice none's drift on the first 20 %).
POOLED_GAIN = 0.10
FULL_CYCLE_SEGMENTS = 3  # heating, cooling and one of them again (the bundled run: cooling, heating, cooling)
CYCLE = f"{FULL_CYCLE_SEGMENTS} or more thermal segments, heating and cooling among them"  # said to the user


@dataclass(frozen=True)
class Candidate:
    """One candidate: a label, the registered method that implements it and its options."""

    label: str
    method: str
    options: dict[str, Any] = field(default_factory=dict)
    stateful: bool = False  # needs the run's whole temperature history (imputed hold-out)


# In order of complexity: of equally good candidates the first one is chosen.
CANDIDATES: tuple[Candidate, ...] = (
    Candidate(NONE, methods.CUBIC, {"degree": 0}),
    Candidate("poly1", methods.CUBIC, {"degree": 1}),
    Candidate("poly2", methods.CUBIC, {"degree": 2}),
    Candidate(methods.CUBIC, methods.CUBIC),
    Candidate(methods.PLA, methods.PLA),
    Candidate(methods.PHYSICS, methods.PHYSICS, stateful=True),
    # the branch offset between heating and cooling, the loop measured on real sensors, fitted whatever the
    # finder says: on the bundled run the finder's structure misses the loop on accel z (CV 3.7 against 2.2 mg)
    Candidate(
        f"{methods.PHYSICS}-branch",
        methods.PHYSICS,
        {"effects": BRANCH_OFFSET.identifier, "given_by": f"auto's candidate {methods.PHYSICS}-branch"},
        stateful=True,
    ),
    # the same offset with every parameter chosen by least squares on the samples (trainer.greybox.least_squares)
    # and the branch at power-on that of a sensor brought to its first temperature from room temperature
    # (T_REF_C): on the bundled run's gyro x, cold starts agree with warm ones and the loop is 44-66 degC
    # wide on every fold, where the finder fitted 1.3 degC on two
    Candidate(
        f"{methods.PHYSICS}-branch-room",
        methods.PHYSICS,
        {
            "effects": BRANCH_OFFSET.identifier,
            "given_by": f"auto's candidate {methods.PHYSICS}-branch-room",
            "play_start_c": T_REF_C,
            "least_squares": True,
        },
        stateful=True,
    ),
    # the same offset as a sum of play operators of widths an octave apart (trainer.greybox.play_sum), started
    # from room temperature: a loop that widens after a larger excursion, as gyro x's of the bundled run does
    # (its cooling from 74 degC, which one width left worse than no compensation)
    Candidate(
        f"{methods.PHYSICS}-branches",
        methods.PHYSICS,
        {
            "effects": BRANCH_OFFSET.identifier,
            "given_by": f"auto's candidate {methods.PHYSICS}-branches",
            "play_start_c": T_REF_C,
            "width_sum": True,
        },
        stateful=True,
    ),
)


def candidate(label: str) -> Candidate:
    return next(c for c in CANDIDATES if c.label == label)


def variant_labels() -> tuple[str, ...]:
    """The candidates that are a registered method with fixed options (``poly1``, ``physics-branches``,
    ...): ``trainer fit --method`` takes them too, so that what auto would ship can be fitted on any
    part of a run and scored on the rest (``trainer evaluate --holdout``)."""
    return tuple(c.label for c in CANDIDATES if c.label != NONE and c.label not in methods.REGISTRY)


def resolved(method: str, options: dict[str, Any] | None) -> tuple[str, dict[str, Any] | None]:
    """(registered method, options) of ``method``: a variant's method with its fixed options over
    ``options`` (its summary names the option that chose it), anything else unchanged."""
    if method not in variant_labels():
        return method, options
    fixed = dict(candidate(method).options)
    if "given_by" in fixed:
        fixed["given_by"] = f"method {method}"
    return candidate(method).method, {**(options or {}), **fixed}


def candidate_list(text: str) -> tuple[str, ...]:
    """``--candidates``: a comma list of candidate labels (argparse type: a bad one is one line)."""
    import argparse

    labels = tuple(dict.fromkeys(x.strip() for x in text.split(",") if x.strip()))
    known = [c.label for c in CANDIDATES]
    bad = [x for x in labels if x not in known]
    if bad or not labels:
        raise argparse.ArgumentTypeError(
            f"unknown candidate {bad[0] if bad else '(empty)'!r}; choose from {','.join(known)}"
        )
    return labels


def row_name(label: str) -> str:
    """A candidate's row in the cross-validation (no compensation is the uncompensated row)."""
    return UNCOMPENSATED if label == NONE else label


@dataclass
class Selection:
    """The cross-validation of every candidate and the one chosen, with the reason in one line."""

    cv: CrossValidation
    chosen: str
    reason: str

    @property
    def candidate(self) -> Candidate:
        return candidate(self.chosen)

    def table(self) -> list[str]:
        return table_lines(self.cv, chosen=row_name(self.chosen))


def shown_name(method: str, stats: TrainStats) -> str:
    """The name a user reads for a fitted model: the candidate ``auto`` chose or the variant asked
    for by name (``poly2``, ``physics-branch``, ``none``: each a registered method with options, which
    ``method``, the registered name that loads it, would misreport as ``poly3`` or ``physics``), else
    ``method``."""
    if stats.selection is not None:
        return str(stats.selection["chosen"])
    return stats.variant if stats.variant is not None else method


def full_cycle(segments: Sequence[Segment]) -> bool:
    """Whether the folds make a whole cycle: at least :data:`FULL_CYCLE_SEGMENTS` segments, heating
    and cooling among them (not the thirds of a run that does not reverse)."""
    labels = {s.label for s in segments}
    return len(segments) >= FULL_CYCLE_SEGMENTS and {LABELS[HEATING], LABELS[COOLING]} <= labels


def _short_run(segments: Sequence[Segment]) -> tuple[str, str]:
    """What a run that is less than a cycle holds, and why its folds extrapolate."""
    kinds = [s.label.split()[0] for s in segments]  # a part of a ramp is labelled "heating 1/3"
    if LABELS[HEATING] in kinds and LABELS[COOLING] in kinds:
        held = " and ".join(f"{kinds.count(k)} {k}" for k in dict.fromkeys(kinds))
        return f"the run holds {held} segment(s)", "each fold extrapolates to a branch it was not trained on"
    return (
        f"the run does not reverse ({' and '.join(dict.fromkeys(kinds))} only; its {len(segments)} folds are parts "
        "of its temperature span)",
        "each fold extrapolates beyond the range it was trained on",
    )


def worst_ratio(cv: CrossValidation, label: str) -> float:
    """The candidate's largest ratio, over every held-out segment started warm and cold, to the better
    of (cubic, no compensation) there: 1.0 is as good as the better of the two everywhere."""
    mine = cv.results[row_name(label)]
    references = [
        cv.results[UNCOMPENSATED],
        *([cv.results[methods.CUBIC]] if methods.CUBIC in cv.results else []),
    ]

    def ratio(mine_rms: float, reference_rms: float) -> float:
        if reference_rms > 0.0:
            return mine_rms / reference_rms
        return 1.0 if mine_rms <= 0.0 else math.inf  # a segment with nothing to remove (a flat channel)

    return max(
        ratio(getattr(mine_fold, start), min(getattr(r.folds[i], start) for r in references))
        for i, mine_fold in enumerate(mine.folds)
        for start in ("warm_rms", "cold_rms")
    )


def leaves_more_than_none(cv: CrossValidation, label: str) -> bool:
    """Whether cross-validation says the candidate is worse than no compensation: its pooled figure,
    over the whole held-out segments or inside the training range, above the uncompensated one (the
    sign-off's guard, :func:`trainer.scoring.verdict.worse_than_uncompensated`, reads the same two)."""
    if label == NONE:
        return False
    mine, raw = cv.results[label], cv.results[UNCOMPENSATED]
    return not (mine.cv_rms < raw.cv_rms and mine.cv_in_range_rms <= raw.cv_in_range_rms)


def _worse_than_none(cv: CrossValidation, label: str) -> str:
    """Which of :func:`leaves_more_than_none`'s two figures refused ``label``, with both values (the
    in-range one is not in the table: "poly3 left more" beside a table where it leaves less misled)."""
    mine, raw = cv.results[label], cv.results[UNCOMPENSATED]
    if mine.cv_rms >= raw.cv_rms:
        return f"{label} left more than no compensation cross-validated ({mine.cv_rms:.4g} against {raw.cv_rms:.4g})"
    return (
        f"{label} left more than no compensation cross-validated inside the training range "
        f"({mine.cv_in_range_rms:.4g} against {raw.cv_in_range_rms:.4g}; {mine.cv_rms:.4g} against "
        f"{raw.cv_rms:.4g} over the whole segments)"
    )


def choose(cv: CrossValidation, refused: dict[str, str] | None = None) -> tuple[str, str]:
    """(label, reason) by the rule of this module's docstring: among the candidates cross-validation
    does not find worse than no compensation, on a whole cycle, of those whose worst held-out
    segment is within :data:`TOLERANCE` of the best such, the least drift pooled (the simplest within
    :data:`POOLED_GAIN`); on less than a cycle the cubic; else none. ``refused``: candidates whose fit
    on the whole run failed :func:`own_run_failure`, with why (they are not chosen)."""
    unit = cv.unit
    refused = refused or {}
    labels = [c.label for c in CANDIDATES if c.label == NONE or c.label in cv.results]
    unsafe = [x for x in labels if leaves_more_than_none(cv, x)]
    allowed = [x for x in labels if x not in unsafe and x not in refused]
    if full_cycle(cv.segments):
        worst = {label: worst_ratio(cv, label) for label in allowed}
        best = min(worst.values())
        safest = [x for x in allowed if worst[x] <= best * (1.0 + TOLERANCE)]
        pooled = {x: cv.results[row_name(x)].cv_rms for x in safest}
        least = min(pooled.values())
        label = next(x for x in safest if pooled[x] <= least * (1.0 + POOLED_GAIN))
        against = (
            "the better of (cubic, uncompensated)"
            if methods.CUBIC in cv.results
            else "uncompensated (the cubic is not among --candidates)"
        )
        reason = (
            f"at worst {worst[label]:.3g}x {against} on any of the {len(cv.segments)} "
            f"held-out segments, warm or cold (within {100 * TOLERANCE:g} % of the best such), and of those the "
            f"least drift cross-validated (the simplest that leaves at most {100 * POOLED_GAIN:g} % more)"
        )
    else:
        label = methods.CUBIC if methods.CUBIC in allowed else NONE
        held, why = _short_run(cv.segments)
        keeps = (
            "auto keeps to the cubic unless it leaves more than no compensation"
            if row_name(methods.CUBIC) in cv.results
            else "auto chooses between the cubic and no compensation, and the cubic is not among --candidates"
        )
        reason = (
            f"{held}: less than a cycle ({CYCLE}); {why} and cannot judge a shape: {keeps}; record a whole "
            "cycle to let it judge the others"
        )
    if unsafe:
        reason += "; " + ", ".join(_worse_than_none(cv, x) for x in unsafe)
    reason += "".join(f"; {why}" for why in refused.values())
    mine, raw = cv.results[row_name(label)], cv.results[UNCOMPENSATED]
    if label == NONE:
        return NONE, f"{reason}: the channel is left uncompensated ({raw.cv_rms:.4g} {unit} cross-validated)"
    return (
        label,
        f"{reason}; it leaves {mine.cv_rms:.4g} {unit} cross-validated (uncompensated {raw.cv_rms:.4g} {unit})",
    )


def own_run_failure(
    selection: Selection, drift: np.ndarray, rec: Recording, smoothing_s: float
) -> str | None:
    """Why the chosen candidate, fitted on the whole run (its estimate ``drift``), is not shipped, or
    None: it must not leave more than no compensation (by more than :data:`TOLERANCE`, and above
    the sign-off's noise margin) anywhere :func:`own_run_figures` scores its own run: each segment,
    the whole run and its heating and cooling rows. Cross-validation scored the fits of the folds,
    each segment about its own constant; the whole run can give the physics finder another structure
    (the bundled run's gyro z, before weakly identified nuisance terms were left out of the fit: a
    warm-up fitted beside the bias polynomial and not compensated, 0.102 deg/s left on the first
    cooling against 0.088 without compensation, where the fold's fit left 0.037), and a level the
    model moves between segments is seen about the run's one constant only."""
    from trainer.data.smoothing import window_samples
    from trainer.scoring.static import noise_floor_mg
    from trainer.scoring.verdict import NOISE_MARGIN

    if selection.chosen == NONE:
        return None
    segments = selection.cv.segments
    mine = own_run_figures(rec, drift, segments, smoothing_s)
    raw = own_run_figures(rec, np.zeros(len(rec)), segments, smoothing_s)
    # as the sign-off's guard: at the noise floor nothing is worse (a segment with no drift to remove,
    # the part of the bundled run's accel y that starts at -4.8 degC: 0.37 against 0.34 mg, floor 0.33)
    window = window_samples(smoothing_s, rec.sample_rate_hz) if smoothing_s > 0 else 1
    floor = noise_floor_mg(np.asarray(rec.accel_mg), window)
    for (where, m), (_, r) in zip(mine, raw, strict=True):
        if m > r * (1.0 + TOLERANCE) and not m <= NOISE_MARGIN * floor:
            unit = selection.cv.unit
            return (
                f"{selection.chosen} fitted on the whole run left more than no compensation on its own "
                f"{where} ({m:.4g} against {r:.4g} {unit}): not the fit cross-validation scored"
            )
    return None


def select(
    rec: Recording,
    *,
    policy: OffsetPolicy | None = None,
    smoothing_s: float = 0.0,
    unit: str = "mg",
    labels: tuple[str, ...] | None = None,
    log: Callable[[str], None] | None = None,
    tasks: TaskMap | None = None,
) -> Selection:
    """Cross-validate the candidates (all, or ``labels``) on ``rec`` and choose one. On less than a
    cycle only the cubic and no compensation can be chosen, so only they are cross-validated (the
    others are listed as not judged, with the reason)."""
    from trainer.fitting import fit_compensator

    wanted = [c for c in CANDIDATES if labels is None or c.label in labels]
    cycle = full_cycle(folds_of(rec.without_truth()))
    chosen = [c for c in wanted if cycle or c.label in (NONE, methods.CUBIC)]

    def fitter(c: Candidate) -> Callable[[Recording], object]:
        return lambda train: fit_compensator(c.method, train, c.options, policy)

    cv = cross_validate(
        rec,
        {c.label: fitter(c) for c in chosen if c.label != NONE},
        stateful={c.label for c in chosen if c.stateful},
        smoothing_s=smoothing_s,
        unit=unit,
        log=log,
        tasks=tasks,
    )
    cv.skipped.update(
        {
            c.label: f"not judged: the run is less than a cycle ({CYCLE}), where cross-validation cannot tell a shape from the noise of one fold"
            for c in wanted
            if c not in chosen
        }
    )
    label, reason = choose(cv)
    return Selection(cv, label, reason)


def selection_record(selection: Selection) -> dict[str, Any]:
    """What the checkpoint keeps of the choice (plain values)."""
    return {
        "chosen": selection.chosen,
        "method": selection.candidate.method,
        "options": dict(selection.candidate.options),
        "reason": selection.reason,
        "rule": f"on a whole cycle, of the candidates within {100 * TOLERANCE:g} % of the smallest worst ratio "
        "to the better of (cubic, uncompensated) over the held-out segments, warm and cold, the simplest within "
        f"{100 * POOLED_GAIN:g} % of the least pooled drift; on less than a "
        "cycle the cubic; never a candidate that leaves more than none pooled, whole or inside the training range",
        "crossval": selection.cv.to_dict(timings=False),
    }


def by_reason(skipped: dict[str, str]) -> dict[str, list[str]]:
    """The candidates not cross-validated, grouped by their reason (one line each)."""
    grouped: dict[str, list[str]] = {}
    for name, why in skipped.items():
        grouped.setdefault(why, []).append(name)
    return grouped


def record_lines(record: dict[str, Any]) -> list[str]:
    """The lines a user reads of a saved selection: segments, the table, the choice."""
    cv = CrossValidation.from_dict(record["crossval"])
    chosen = row_name(str(record["chosen"]))
    return [
        f"auto: cross-validation over {len(cv.segments)} thermal segments of {cv.source}:",
        *segment_lines(cv.segments),
        *table_lines(cv, chosen=chosen),
        *[f"- {', '.join(names)}: {why}" for why, names in by_reason(cv.skipped).items()],
        f"auto: chose {record['chosen']}: {record['reason']}",
    ]


def identity_note(train_stats: TrainStats, source: str) -> str | None:
    """One line for an export of a model that ``auto`` left uncompensated (None otherwise)."""
    record = train_stats.selection
    if record is None or record.get("chosen") != NONE:
        return None
    channel = train_stats.channel or "the channel"
    return (
        f"{source}: {channel} is exported as the identity (C: zero correction; flight-stack parameters: zero "
        f"coefficients, which ArduPilot applies with INS_TCALn_ENABLE 1 as no correction): "
        f"{record.get('reason', 'auto chose none')}"
    )


@dataclass(frozen=True)
class CrossValidatedFigures:
    """A saved selection's pooled figures for the chosen model and the uncompensated output, whole and
    inside the training range: the two comparisons :func:`leaves_more_than_none` made."""

    model: float
    uncompensated: float
    model_in_range: float
    uncompensated_in_range: float
    segments: int
    per_segment: tuple[SegmentFigures, ...] = ()  # each held-out segment at its natural start


def cross_validated_figures(record: dict[str, Any]) -> CrossValidatedFigures:
    """The chosen model's and the uncompensated pooled cross-validated drift left of a saved selection."""
    cv = CrossValidation.from_dict(record["crossval"])
    mine = cv.results[row_name(str(record["chosen"]))]
    raw = cv.results[UNCOMPENSATED]
    per_segment = tuple(
        SegmentFigures(segment.name, m, u)
        for segment, m, u in zip(cv.segments, mine.natural(), raw.natural(), strict=True)
    )
    return CrossValidatedFigures(
        mine.cv_rms, raw.cv_rms, mine.cv_in_range_rms, raw.cv_in_range_rms, len(cv.segments), per_segment
    )


def fit_with_selection(
    method: str,
    train: Recording,
    options: dict[str, Any] | None = None,
    policy: OffsetPolicy | None = None,
    log: Callable[[str], None] | None = None,
    tasks: TaskMap | None = None,
) -> tuple[Any, TrainStats]:
    """:func:`trainer.fitting.fit_with_stats`, with ``auto`` resolved first: the candidates are
    cross-validated on ``train``, the chosen one is fitted on the whole of it (:func:`ship`), and
    ``train_stats.selection`` records the table that chose it."""
    from trainer.data.channels import UNIT_LABELS, channel_unit
    from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
    from trainer.fitting import fit_with_stats

    if method != AUTO:
        registered, fixed = resolved(method, options)
        model, stats = fit_with_stats(registered, train, fixed, policy)
        return model, (replace(stats, variant=method) if method in variant_labels() else stats)
    selection = select(
        train,
        labels=(options or {}).get("candidates"),
        policy=policy,
        smoothing_s=PAPER_RUN_SMOOTHING_S,
        unit=UNIT_LABELS[channel_unit(train)],
        log=log,
        tasks=tasks,
    )
    model, stats, _ = ship(selection, train, policy, log)
    return model, stats


def ship(
    selection: Selection,
    train: Recording,
    policy: OffsetPolicy | None = None,
    log: Callable[[str], None] | None = None,
) -> tuple[Any, TrainStats, Selection]:
    """The chosen candidate fitted on the whole of ``train``, its ``train_stats`` with the selection
    record, and the selection as shipped: a fit that fails :func:`own_run_failure` is refused and the
    rule chooses again without it (no compensation never fails)."""
    from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
    from trainer.fitting import fit_with_stats

    refused: dict[str, str] = {}
    while True:
        model, stats = fit_with_stats(selection.candidate.method, train, selection.candidate.options, policy)
        drift = model.predict_drift(train.without_truth())
        why = own_run_failure(selection, drift, train, PAPER_RUN_SMOOTHING_S)
        if why is None:
            return model, replace(stats, selection=selection_record(selection)), selection
        if log is not None:
            log(f"auto: {why}; choosing again without it")
        refused[selection.chosen] = why
        selection = Selection(selection.cv, *choose(selection.cv, refused))
