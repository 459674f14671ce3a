"""The one sign-off verdict of ``trainer report`` and ``trainer fleet``, and its built-in guard.

A verdict is a function of checks (each passed or failed, one line each) and of reasons for a
human review: FAIL when any check fails; NO VERDICT when no *decisive* check was made (a report
without thresholds: a guard alone can fail a unit but cannot pass it); REVIEW when every check
passes but something asks for a look (the fleet's out-of-family units); PASS otherwise.

The guard every sign-off carries, :func:`worse_than_uncompensated`, takes plain per-part figures
(:class:`Figures`) rather than a recording, so that any scoring (one hold-out split today,
cross-validated thermal segments later) can feed it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

PASS, REVIEW, FAIL, NO_VERDICT = "PASS", "REVIEW", "FAIL", "NO VERDICT"


class Outcome(Protocol):
    """A check as the verdict sees it."""

    @property
    def ok(self) -> bool: ...

    @property
    def decisive(self) -> bool:
        """True: a pass counts towards PASS; False: a guard, whose pass alone says nothing."""
        ...

    @property
    def name(self) -> str:
        """What was checked, as the verdict line lists a failure."""
        ...


@dataclass(frozen=True)
class Figures:
    """A model's drift left on data it was not trained on, beside the uncompensated output's.

    Plain numbers in the channel's unit (RMS about one constant, :mod:`trainer.scoring.static`);
    NaN: not measured (e.g. no in-range figures because every sample is inside the trained range).
    ``basis`` says where they come from ("held-out", "all samples (in-sample)", ...).
    """

    basis: str
    model_rms: float
    uncompensated_rms: float
    model_in_range_rms: float = math.nan
    uncompensated_in_range_rms: float = math.nan
    noise_floor: float = math.nan
    unit: str = "mg"


@dataclass(frozen=True)
class Guard:
    """The built-in check: compensation must not leave more drift than no compensation."""

    subject: str
    ok: bool
    detail: str  # one line: the comparison that decided
    decisive: bool = False

    @property
    def name(self) -> str:
        return f"{self.subject} {self.detail}"


# A drift left within this factor of the noise floor is noise: a model that is "worse" only there is not.
NOISE_MARGIN = 1.2
# Figures this close are one figure: a model that shifts the output by a constant (a cubic holding its
# end value beyond the trained range) leaves the uncompensated RMS up to floating-point rounding.
TIE_RELATIVE = 1e-9


def _worse(model: float, uncompensated: float, floor: float) -> bool:
    if not (math.isfinite(model) and math.isfinite(uncompensated)):
        return False
    if math.isfinite(floor) and model <= NOISE_MARGIN * floor:
        return False
    return model > uncompensated and not math.isclose(model, uncompensated, rel_tol=TIE_RELATIVE)


def worse_than_uncompensated(subject: str, figures: Figures) -> Guard:
    """Fails when the model's drift left (whole part, or in range) exceeds the uncompensated output's."""
    f = figures
    if not math.isfinite(f.model_rms) and math.isfinite(f.uncompensated_rms):
        return Guard(
            subject,
            False,
            f"the model's output is not finite ({f.basis} drift left {f.model_rms}): a NaN or an infinity in its "
            "parameters or its arithmetic",
        )
    for where, model, raw in (
        (f.basis, f.model_rms, f.uncompensated_rms),
        (f"{f.basis} in range", f.model_in_range_rms, f.uncompensated_in_range_rms),
    ):
        if _worse(model, raw, f.noise_floor):
            return Guard(
                subject,
                False,
                f"worse than uncompensated: {where} drift left {model:.4g} {f.unit} RMS > {raw:.4g} {f.unit} "
                "without the model",
            )
    if math.isclose(f.model_rms, f.uncompensated_rms, rel_tol=TIE_RELATIVE):
        return Guard(
            subject,
            True,
            f"no better than uncompensated: {f.basis} drift left {f.model_rms:.4g} {f.unit} RMS, the same "
            "as without the model (the identity, auto's none; or a model holding its edge value outside its "
            "trained range, which shifts the output by a constant)",
        )
    if f.model_rms >= f.uncompensated_rms:  # not worse only because it is noise (_worse's margin)
        return Guard(
            subject,
            True,
            f"at the noise floor: {f.basis} drift left {f.model_rms:.4g} {f.unit} RMS, {f.uncompensated_rms:.4g} "
            f"{f.unit} without the model, within {NOISE_MARGIN:g}x the noise floor ({f.noise_floor:.4g} {f.unit}): "
            "not worse",
        )
    return Guard(
        subject,
        True,
        f"better than uncompensated: {f.basis} drift left {f.model_rms:.4g} {f.unit} RMS < "
        f"{f.uncompensated_rms:.4g} {f.unit} without the model",
    )


@dataclass(frozen=True)
class SegmentFigures:
    """One part of a scored run: a held-out segment of a cross-validation (at its natural start), or
    the heating or cooling rows of a part; the model's drift left there beside the uncompensated
    output's, in the channel's unit."""

    name: str  # e.g. "cooling 3134-4245 s (73.9 -> 36.3 degC)", "cooling rows"
    model_rms: float
    uncompensated_rms: float


def undetermined_reason(label: str, undetermined: Sequence[str]) -> str | None:
    """The review reason for a model that carries parameters its training run does not determine
    (:meth:`trainer.compensator.Compensator.undetermined`), or None."""
    if not undetermined:
        return None
    return f"{label} carries what its training run does not determine: {'; '.join(undetermined)}"


# Below this share of the scored temperature span inside the trained range the figures are of the
# clamp (every model holds its edge value outside the range), not of the model: a hold-out that
# shares only its boundary sample with the training part has a coverage of a few 1e-5.
MIN_SCORED_COVERAGE = 0.05


def outside_trained_range(label: str, coverage: float) -> str | None:
    """A review reason when (almost) none of the scored temperature span lies inside the trained range
    (coverage below :data:`MIN_SCORED_COVERAGE`): there every model holds its edge value, so the
    figures judge that constant, not the model."""
    if coverage >= MIN_SCORED_COVERAGE:
        return None
    return (
        f"{label}: scored outside its trained temperature range ({100 * coverage:.2g} % of the scored span "
        f"inside it, under {100 * MIN_SCORED_COVERAGE:g} %): there it holds its edge value, so the figures say "
        "nothing of the model; score a part inside the range (another --holdout, or a second run)"
    )


def worse_on_a_part(
    subject: str, where: str, parts: Sequence[SegmentFigures], noise_floor: float, unit: str
) -> str | None:
    """A reason for a human look when the model leaves more than no compensation (beyond the noise)
    on one of ``parts`` of what it is scored on, though not over all of it (the guard's figure): a
    user meets one part at a time. ``where`` prefixes the part's name ("held-out "). None when no
    part is worse."""
    worse = [s for s in parts if _worse(s.model_rms, s.uncompensated_rms, noise_floor)]
    if not worse:
        return None
    s = max(worse, key=lambda x: x.model_rms / x.uncompensated_rms)
    return (
        f"{subject}: on the {where}{s.name} it leaves {s.model_rms:.4g} {unit}, "
        f"{s.model_rms / s.uncompensated_rms:.2f}x uncompensated ({s.uncompensated_rms:.4g} {unit})"
    )


def worse_on_a_segment(
    subject: str, segments: Sequence[SegmentFigures], noise_floor: float, unit: str
) -> str | None:
    """:func:`worse_on_a_part` over a cross-validation's held-out segments."""
    return worse_on_a_part(subject, "held-out ", segments, noise_floor, unit)


@dataclass(frozen=True)
class Verdict:
    status: str  # PASS | REVIEW | FAIL | NO VERDICT
    failed: tuple[str, ...] = ()  # the failed checks' names
    review: tuple[str, ...] = ()  # why a human should look (REVIEW)

    def line(self) -> str:
        """The status with what decided it, on one line."""
        if self.failed:
            return f"{self.status} (failed: {'; '.join(self.failed)})"
        if self.status == REVIEW:
            return f"{self.status} ({'; '.join(self.review)})"
        return self.status


def verdict(
    figures: Mapping[str, Figures], checks: Sequence[Outcome] = (), review: Sequence[str] = ()
) -> Verdict:
    """FAIL, NO VERDICT, REVIEW or PASS (module docstring).

    ``figures``: subject (a channel and method, a unit and method) -> its held-out figures, each
    guarded by :func:`worse_than_uncompensated`; ``checks``: the thresholds' and the pipeline's
    (verification, stages); ``review``: reasons for a human look."""
    guards = [worse_than_uncompensated(subject, f) for subject, f in figures.items()]
    failed = tuple(c.name for c in [*guards, *checks] if not c.ok)
    if failed:
        return Verdict(FAIL, failed, tuple(review))
    if not any(c.decisive for c in checks):
        return Verdict(NO_VERDICT, (), tuple(review))
    return Verdict(REVIEW if review else PASS, (), tuple(review))
