"""Choosing the left-out effects: forward selection by BIC, then telling confounded ones apart.

The criterion is the BIC of the GLS likelihood with the noise covariance re-estimated for every
model (so correlated noise does not pass for an effect): an effect joins when it lowers the BIC
by at least ``THRESHOLD`` (10, "very strong" on the Kass-Raftery scale), one at a time, best first,
until nothing passes. Afterwards every chosen effect is swapped for each effect it is known to be
confounded with (thermal_lag with temp_rate, hysteresis or stress_relaxation, ...); when the swap
costs less than ``AMBIGUOUS`` (6) in BIC, the data cannot tell them apart and both are reported.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from tqdm import tqdm

from trainer.diagnose.blocks import BlockData
from trainer.diagnose.candidates import Proposal, propose
from trainer.diagnose.model import ModelFit, Term, fit_model

THRESHOLD = 10.0
AMBIGUOUS = 6.0
TOP_REFIT = 3
MAX_ADDED = 4

CONFUSABLE: dict[str, tuple[str, ...]] = {
    "thermal_lag": ("temp_rate", "hysteresis", "stress_relaxation"),
    "temp_rate": ("thermal_lag", "hysteresis"),
    "hysteresis": ("thermal_lag", "temp_rate"),
    "stress_relaxation": ("thermal_lag", "warmup"),
    "warmup": ("stress_relaxation", "bias_step"),
    "bias_step": ("warmup",),
    "rate_ramp": ("rate_random_walk",),
    "rate_random_walk": ("rate_ramp",),
}

SEPARATING_SIGNATURE: dict[frozenset[str], str] = {
    frozenset({"thermal_lag", "temp_rate"}): (
        "a lag scales with the local slope of the bias curve and settles with its own time constant "
        "after a ramp corner; a dT/dt term follows the rate itself"
    ),
    frozenset({"thermal_lag", "hysteresis"}): (
        "a lag offset decays during a hold and grows with the ramp rate; a hysteresis offset "
        "persists in a hold and does not depend on the rate"
    ),
    frozenset({"temp_rate", "hysteresis"}): (
        "a dT/dt offset vanishes in a hold and scales with the rate; a hysteresis offset persists"
    ),
    frozenset({"thermal_lag", "stress_relaxation"}): (
        "the time constant: a lag settles within minutes (10-900 s), package creep over 20 min to hours"
    ),
    frozenset({"bias_step", "warmup"}): (
        "a step is instantaneous and permanent; a warm-up decays exponentially from power-on (a longer "
        "soak after power-on, or a higher sample rate at the start, shows the shape)"
    ),
    frozenset({"stress_relaxation", "warmup"}): (
        "creep follows each temperature change; warm-up happens once after power-on"
    ),
    frozenset({"rate_ramp", "rate_random_walk"}): (
        "a ramp is a straight line in time; a random walk wanders (its Allan slope is +1/2, the ramp's +1)"
    ),
}


@dataclass
class Step:
    """One accepted effect and the fit it produced."""

    effect: str
    fit: ModelFit
    delta_bic: float
    evidence: str
    term_index: int | None  # index of the new term in fit.terms (None for noise terms)


@dataclass
class Tested:
    effect: str
    delta_bic: float
    note: str = ""


@dataclass
class Selection:
    steps: list[Step]
    final: ModelFit
    tested_first_round: list[Tested]
    # (effect, occurrence) -> (BIC lost when the effect is dropped from the final model, that model)
    drop_one: dict[tuple[str, int], tuple[float, ModelFit]] = field(default_factory=dict)
    ambiguous: list[dict[str, object]] = field(default_factory=list)


def _score_fixed(current: ModelFit, proposal: Proposal) -> float:
    if proposal.spectral_evidence is not None:
        return proposal.spectral_evidence - 3.0 * math.log(max(proposal.spectral_n, 2))
    if proposal.fit_fixed_noise is None:
        return math.inf  # a noise term: only the ML refit can score it
    return current.bic - proposal.fit_fixed_noise.bic


def refit(current: ModelFit, proposal: Proposal, data: BlockData) -> tuple[ModelFit, float, str]:
    """The proposal with its noise ML-refitted; returns (fit, delta BIC vs current, evidence text)."""
    if proposal.spectral_evidence is not None:
        fit = proposal.fit_fixed_noise
        assert fit is not None
        delta = proposal.spectral_evidence - 3.0 * math.log(max(proposal.spectral_n, 2))
        fit = fit_model(fit.terms, fit.noise.terms, data, gls=current.gls, refit_noise=False)
        return fit, delta, f"BIC improvement {delta:.1f} ({proposal.note})"
    fit = fit_model(proposal.terms, proposal.noise_terms, data, start=current.noise)
    delta = current.bic - fit.bic
    return fit, delta, f"BIC improvement {delta:.1f} (GLS, noise re-estimated)"


def _new_term_index(before: ModelFit, after: ModelFit) -> int | None:
    if len(after.terms) == len(before.terms):
        return None
    return len(after.terms) - 1


def forward_select(
    baseline: ModelFit, data: BlockData, candidates: Sequence[str], *, progress: bool = False
) -> Selection:
    """Add the best candidate while the BIC improves by ``THRESHOLD`` or more."""
    current = baseline
    steps: list[Step] = []
    first_round: list[Tested] = []
    bar = tqdm(total=MAX_ADDED, desc="diagnose: search", unit="round", disable=None if progress else True, leave=False)
    for round_index in range(MAX_ADDED):
        proposals = [p for effect in candidates for p in propose(current, data, effect)]
        scored = sorted(proposals, key=lambda p: -_score_fixed(current, p))
        results: list[tuple[float, ModelFit, Proposal, str]] = []
        refits = 0
        for proposal in scored:
            score = _score_fixed(current, proposal)
            is_noise = proposal.fit_fixed_noise is None
            if proposal.spectral_evidence is None and not is_noise and refits >= TOP_REFIT and score < THRESHOLD:
                if round_index == 0:
                    first_round.append(Tested(proposal.effect, score, "fixed-noise BIC (not refitted)"))
                continue
            fit, delta, text = refit(current, proposal, data)
            refits += 0 if is_noise or proposal.spectral_evidence is not None else 1
            results.append((delta, fit, proposal, text))
            if round_index == 0:
                first_round.append(Tested(proposal.effect, delta, text))
        bar.update()
        if not results:
            break
        delta, fit, proposal, text = max(results, key=lambda item: item[0])
        if delta < THRESHOLD:
            break
        steps.append(Step(proposal.effect, fit, delta, text, _new_term_index(current, fit)))
        current = fit
    bar.close()
    best_first: dict[str, Tested] = {}
    for item in first_round:
        if item.effect not in best_first or item.delta_bic > best_first[item.effect].delta_bic:
            best_first[item.effect] = item
    return Selection(steps, current, sorted(best_first.values(), key=lambda t: -t.delta_bic))


def drop_term(final: ModelFit, index: int | None, effect: str, data: BlockData) -> ModelFit:
    """The final model without one term (or noise term), refitted."""
    if index is None:
        noise = tuple(t for t in final.noise.terms if t != effect)
        return fit_model(final.terms, noise, data, start=final.noise)
    terms = tuple(t for k, t in enumerate(final.terms) if k != index)
    return fit_model(terms, final.noise.terms, data, start=final.noise)


def resolve(selection: Selection, data: BlockData, identifiable: set[str], *, progress: bool = False) -> None:
    """Importance of each chosen effect (BIC lost when dropped) and ambiguity with confounders."""
    final = selection.final
    indices = _final_indices(selection)
    items = list(indices.items())
    bar = tqdm(items, desc="diagnose: confounders", unit="effect", disable=None if progress else True, leave=False)
    for (effect, occurrence), index in bar:
        reduced = drop_term(final, index, effect, data)
        if index is not None and final.terms[index].offset is not None:
            step = next(s for s in selection.steps if s.term_index == index)
            importance = step.delta_bic
        else:
            importance = reduced.bic - final.bic
        selection.drop_one[(effect, occurrence)] = (importance, reduced)
        for alternative in CONFUSABLE.get(effect, ()):
            if alternative not in identifiable or alternative in final.identifiers:
                continue
            if alternative in final.noise.terms:
                continue
            proposals = propose(reduced, data, alternative)
            if not proposals:
                continue
            swapped = [refit(reduced, p, data)[0] for p in proposals]
            best = min(swapped, key=lambda f: f.bic)
            gap = best.bic - final.bic
            if gap < AMBIGUOUS:
                selection.ambiguous.append(
                    {
                        "effects": [effect, alternative],
                        "delta_bic": round(gap, 2),
                        "preferred": effect if gap >= 0 else alternative,
                        "reason": (
                            f"replacing {effect} by {alternative} changes the BIC by only {gap:+.1f} "
                            f"(< {AMBIGUOUS:g}); what would separate them: "
                            + SEPARATING_SIGNATURE.get(frozenset({effect, alternative}), "a different test profile")
                        ),
                    }
                )
    bar.close()


def _final_indices(selection: Selection) -> dict[tuple[str, int], int | None]:
    """(effect, occurrence) -> term index in the final model for every accepted step."""
    final = selection.final
    out: dict[tuple[str, int], int | None] = {}
    seen: dict[str, int] = {}
    for step in selection.steps:
        occurrence = seen.get(step.effect, 0)
        seen[step.effect] = occurrence + 1
        if step.effect in final.noise.terms and step.term_index is None:
            out[(step.effect, occurrence)] = None
            continue
        positions = [k for k, term in enumerate(final.terms) if term.identifier == step.effect]
        out[(step.effect, occurrence)] = positions[occurrence] if occurrence < len(positions) else None
    return out


def final_indices(selection: Selection) -> dict[tuple[str, int], int | None]:
    return _final_indices(selection)


def baseline_support(baseline: ModelFit, data: BlockData, user_terms: Sequence[Term]) -> list[dict[str, object]]:
    """Effects of the user's simulation that the data do not support (dropping them lowers the BIC)."""
    out = []
    for index, term in enumerate(baseline.terms):
        if term.identifier == "bias_poly" or term not in user_terms:
            continue
        reduced = drop_term(baseline, index, term.identifier, data)
        gain = baseline.bic - reduced.bic
        if gain > 0:
            out.append(
                {
                    "effect": term.identifier,
                    "delta_bic": round(-gain, 2),
                    "reason": f"dropping it lowers the BIC by {gain:.1f}: the recording does not need it",
                }
            )
    return out


