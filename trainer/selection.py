"""``--method auto``: per channel, the compensator that cross-validation says leaves the least drift.

The candidates (:data:`CANDIDATES`, declared here once): no compensation, polynomials of order 1
to 3 in temperature (the flight stacks' cubic and the lower orders that do not over-fit a short
range), PLA and the physics compensator, with its automatic structure and with the branch offset. Each is cross-validated over
the run's thermal segments (:mod:`trainer.scoring.crossval`); the choice is the simplest candidate
whose pooled cross-validated drift left is within :data:`TOLERANCE` of the best one (a more
complex model must earn its place), and never one that leaves more than no compensation: then the
choice is ``none``, which exports as the identity (C) or a disabled entry (flight-stack parameters).

What is fitted and saved is the chosen candidate, trained on the whole run; the checkpoint's
``train_stats.selection`` keeps the table that chose it (:func:`selection_record`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from trainer import methods
from trainer.data.recording import Recording
from trainer.physics.catalogue.hysteresis_offset import DEFINITION as BRANCH_OFFSET
from trainer.reference import OffsetPolicy
from trainer.scoring.crossval import (
    UNCOMPENSATED,
    CrossValidation,
    cross_validate,
    segment_lines,
    table_lines,
)
from trainer.train_stats import TrainStats

AUTO = "auto"  # the selector's name on the command line (trainer fit --method auto)
NONE = "none"  # the candidate "no compensation" (a polynomial of order 0: zero drift)
TOLERANCE = 0.02  # a candidate within 2 % of the best counts as as good (the simpler one wins)


@dataclass(frozen=True)
class Candidate:
    """One candidate: a label, the registered method that implements it and its options."""

    label: str
    method: str
    options: dict[str, Any] = field(default_factory=dict)
    stateful: bool = False  # needs the run's whole temperature history (imputed hold-out)


# In order of complexity: the first one within TOLERANCE of the best is chosen.
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
        f"{methods.PHYSICS}-branch", methods.PHYSICS, {"effects": BRANCH_OFFSET.identifier}, stateful=True
    ),
)


def candidate(label: str) -> Candidate:
    return next(c for c in CANDIDATES if c.label == label)


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
        return table_lines(self.cv, chosen=UNCOMPENSATED if self.chosen == NONE else self.chosen)


def choose(cv: CrossValidation) -> tuple[str, str]:
    """(label, reason): the simplest candidate within :data:`TOLERANCE` of the best pooled figure;
    ``none`` when no candidate leaves less than the uncompensated output."""
    unit = cv.unit
    raw = cv.results[UNCOMPENSATED].cv_rms
    scores = {
        c.label: cv.results[c.label].cv_rms for c in CANDIDATES if c.label in cv.results and c.label != NONE
    }
    best = min(scores.values(), default=raw)
    if not best < raw:
        return NONE, (
            f"no candidate leaves less drift than no compensation held out (uncompensated {raw:.4g} {unit}, "
            f"best candidate {best:.4g} {unit}): the channel is left uncompensated"
        )
    for label, score in scores.items():
        if score <= best * (1.0 + TOLERANCE):
            return label, (
                f"{label} leaves {score:.4g} {unit} cross-validated (uncompensated {raw:.4g} {unit}, best "
                f"{best:.4g} {unit}; the simplest candidate within {100 * TOLERANCE:g} % of the best is chosen)"
            )
    raise AssertionError("the best candidate is within the tolerance of itself")


def select(
    rec: Recording,
    *,
    policy: OffsetPolicy | None = None,
    smoothing_s: float = 0.0,
    unit: str = "mg",
    labels: tuple[str, ...] | None = None,
    log: Callable[[str], None] | None = None,
) -> Selection:
    """Cross-validate the candidates (all, or ``labels``) on ``rec`` and choose one."""
    from trainer.fitting import fit_compensator

    chosen = [c for c in CANDIDATES if labels is None or c.label in labels]

    def fitter(c: Candidate) -> Callable[[Recording], object]:
        return lambda train: fit_compensator(c.method, train, c.options, policy)

    cv = cross_validate(
        rec,
        {c.label: fitter(c) for c in chosen if c.label != NONE},
        stateful={c.label for c in chosen if c.stateful},
        smoothing_s=smoothing_s,
        unit=unit,
        log=log,
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
        "rule": f"simplest candidate within {100 * TOLERANCE:g} % of the best pooled cross-validated drift left; "
        "none when no candidate beats no compensation",
        "crossval": selection.cv.to_dict(),
    }


def record_lines(record: dict[str, Any]) -> list[str]:
    """The lines a user reads of a saved selection: segments, the table, the choice."""
    cv = CrossValidation.from_dict(record["crossval"])
    chosen = UNCOMPENSATED if record["chosen"] == NONE else str(record["chosen"])
    return [
        f"auto: cross-validation over {len(cv.segments)} thermal segments of {cv.source}:",
        *segment_lines(cv.segments),
        *table_lines(cv, chosen=chosen),
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
        f"coefficients, the sensor disabled where every axis is so): {record.get('reason', 'auto chose none')}"
    )


def cross_validated_figures(record: dict[str, Any]) -> tuple[float, float, int]:
    """(chosen model's, uncompensated) pooled cross-validated drift left of a saved selection, and
    the number of segments."""
    cv = CrossValidation.from_dict(record["crossval"])
    chosen = UNCOMPENSATED if record["chosen"] == NONE else str(record["chosen"])
    return cv.results[chosen].cv_rms, cv.results[UNCOMPENSATED].cv_rms, len(cv.segments)


def fit_with_selection(
    method: str,
    train: Recording,
    options: dict[str, Any] | None = None,
    policy: OffsetPolicy | None = None,
    log: Callable[[str], None] | None = None,
) -> tuple[Any, TrainStats]:
    """:func:`trainer.fitting.fit_with_stats`, with ``auto`` resolved first: the candidates are
    cross-validated on ``train``, the chosen one is fitted on the whole of it, and
    ``train_stats.selection`` records the table that chose it."""
    from trainer.data.channels import UNIT_LABELS, channel_unit
    from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
    from trainer.fitting import fit_with_stats

    if method != AUTO:
        return fit_with_stats(method, train, options, policy)
    selection = select(
        train,
        labels=(options or {}).get("candidates"),
        policy=policy,
        smoothing_s=PAPER_RUN_SMOOTHING_S,
        unit=UNIT_LABELS[channel_unit(train)],
        log=log,
    )
    model, stats = fit_with_stats(selection.candidate.method, train, selection.candidate.options, policy)
    return model, replace(stats, selection=selection_record(selection))
