"""A profile's row of the table (identification rate, parameter error, drift left against the cubic)
and the one judgement of it against the target (:meth:`Summary.verdict`), with every wording of that
judgement: the table's target column, the candidate log and the headline of report and terminal."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from trainer.plan.montecarlo import CUBIC, PHYSICS, DrawResult
from trainer.plan.priors import Prior


@dataclass(frozen=True)
class Target:
    """Done when: every effect identified (found, checked parameters within ``tolerance``) in at least
    ``identify_rate`` of the draws, and physics leaving at most ``vs_cubic`` times the cubic (median)."""

    identify_rate: float = 0.95
    tolerance: float = 0.25
    vs_cubic: float = 0.5


class Verdict(Enum):
    """A profile against the target: judged once (:meth:`Summary.verdict`), worded from here alone."""

    MET = "met"  # the point estimates reach the target and the draws show the identification rate
    TOO_FEW = "too few draws"  # the point estimates reach it, the rate's lower bound is below the asked
    NOT_MET = "not met"  # a point estimate misses it


def draws_text(count: int) -> str:
    return f"{count} draw{'' if count == 1 else 's'}"


@dataclass(frozen=True)
class Summary:
    name: str
    duration_s: float
    draws: int
    identified: dict[str, float]  # effect -> share of draws
    median_error: dict[str, float]  # effect -> median largest relative error where found (nan: never)
    drift_left: dict[str, float]  # method -> median RMS over draws
    ratio_median: float
    ratio_max: float

    def meets(self, target: Target) -> bool:
        """The point estimates reach the target (what the search asks of a candidate); whether the draws
        show it is :meth:`verdict`'s to say."""
        return (
            all(v >= target.identify_rate for v in self.identified.values())
            and self.ratio_median <= target.vs_cubic
        )

    def lower_bound(self) -> float:
        """The :data:`CONFIDENCE` lower bound on the least identified effect's rate."""
        least = min(self.identified.values(), default=1.0)
        return rate_lower_bound(round(least * self.draws), self.draws)

    def verdict(self, target: Target) -> Verdict:
        """The judgement every output words (a point estimate met in too few draws is not called met)."""
        if not self.meets(target):
            return Verdict.NOT_MET
        return Verdict.MET if self.lower_bound() >= target.identify_rate else Verdict.TOO_FEW

    def verdict_label(self, target: Target) -> str:
        """The judgement in a few words: the table's target column and the candidate log."""
        verdict = self.verdict(target)
        if verdict is Verdict.TOO_FEW:
            return f"not shown, too few draws (lower bound {100 * self.lower_bound():.0f} %)"
        return verdict.value

    def verdict_text(self, target: Target) -> str:
        """The judgement in a sentence, for the report and the terminal alike: with a met target, the draws
        and the one-sided lower bound on the least identified effect's rate (1 draw of 1 shows 5 %, not
        the 95 % asked); with too few draws, what was measured instead; else what it cannot reach."""
        verdict = self.verdict(target)
        if verdict is Verdict.NOT_MET:
            return "does not meet the target; it cannot reach: " + "; ".join(self.short_of(target))
        bound = f"a one-sided {100 * CONFIDENCE:g} % lower bound of {100 * self.lower_bound():.0f} %"
        if verdict is Verdict.MET:
            return (
                f"meets the target in {draws_text(self.draws)}; on {draws_text(self.draws)} the least "
                f"identified effect's rate has {bound}"
            )
        least = min(self.identified.values(), default=1.0)
        return (
            f"{draws_text(self.draws)}, too few to show the target: the least identified effect was "
            f"identified in {100 * least:.0f} % of them and physics left {self.ratio_median:.2f}x the cubic "
            f"(median), but on {draws_text(self.draws)} that rate has {bound}, below the "
            f"{100 * target.identify_rate:g} % asked (more --draws)"
        )

    def short_of(self, target: Target) -> list[str]:
        """What this profile does not reach (empty: the target is met)."""
        out = [
            f"{name} identified in {100 * v:.0f} % of draws (< {100 * target.identify_rate:.0f} %)"
            for name, v in self.identified.items()
            if v < target.identify_rate
        ]
        if not self.ratio_median <= target.vs_cubic:
            out.append(f"physics leaves {self.ratio_median:.2f}x the cubic (> {target.vs_cubic:g}x)")
        return out


CONFIDENCE = 0.95  # of the one-sided lower bound the report gives beside an identification rate


def rate_lower_bound(successes: int, draws: int, confidence: float = CONFIDENCE) -> float:
    """The one-sided Clopper-Pearson lower bound on a rate seen ``successes`` times in ``draws``: what
    a few draws can show (2 of 2: 22 %; 20 of 20: 86 %)."""
    from scipy.stats import beta

    if successes <= 0:
        return 0.0
    return float(beta.ppf(1.0 - confidence, successes, draws - successes + 1))


def identified(result: DrawResult, target: Target) -> bool:
    return all(e <= target.tolerance for e in result.error.values())


def summarise(
    name: str, duration_s: float, results: list[DrawResult], priors: tuple[Prior, ...], target: Target
) -> Summary:
    rates, errors = {}, {}
    for prior in priors:
        err = np.array([r.error[prior.identifier] for r in results])
        rates[prior.identifier] = float(np.mean(err <= target.tolerance))
        found = err[np.isfinite(err)]
        errors[prior.identifier] = float(np.median(found)) if found.size else math.nan
    ratios = np.array([r.ratio for r in results])
    left = {m: float(np.median([r.drift_left[m] for r in results])) for m in (PHYSICS, CUBIC)}
    return Summary(
        name, duration_s, len(results), rates, errors, left, float(np.median(ratios)), float(np.max(ratios))
    )
