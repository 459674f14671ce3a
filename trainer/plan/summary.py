"""A profile's row of the table (identification rate, parameter error, drift left against the cubic)
and whether it meets the target."""

from __future__ import annotations

import math
from dataclasses import dataclass

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
        return (
            all(v >= target.identify_rate for v in self.identified.values())
            and self.ratio_median <= target.vs_cubic
        )

    def lower_bound(self) -> float:
        """The :data:`CONFIDENCE` lower bound on the least identified effect's rate."""
        least = min(self.identified.values(), default=1.0)
        return rate_lower_bound(round(least * self.draws), self.draws)

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
