"""A best fit with an implausible parameter is reported as ambiguous, not named.

When the effect the search would name fits with a parameter outside the catalogue's plausible
range (a creep gain nine times the largest plausible one), the shape is right but the physics
probably is not: a plausible confounder (or two together) may describe the same residual. Each of
the effect's ``confounders`` is fitted in its place, singly and in pairs, and the choice is reported
as one :class:`~trainer.diagnose.result.Ambiguity` listing the candidates and their BIC differences.

One case is no ambiguity: a plausible confounder that, fitted in the implausible term's place, gives
a *lower* BIC than the search's model. The search missed it (its swap step keeps an effect's
confounders out: which of two to name is the ambiguity step's call), and the ambiguity step names it
(:func:`prefer_plausible`): the better fit and the plausible physics agree. On the bundled accel x
at 0.5 Hz with a 1.12 mg branch offset added, the search named a `hysteresis` of 2.32 mg (plausible
up to 2) where the `hysteresis_offset` added fits 3.2 lower in BIC, and the report named nothing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from itertools import combinations

from trainer.diagnose.blocks import BlockData
from trainer.diagnose.model import ModelFit, catalogue_effects
from trainer.diagnose.result import Alternative, Ambiguity, LeftOut
from trainer.diagnose.select import (
    CONFUSABLE,
    NOISE_EFFECTS,
    SEPARATING_SIGNATURE,
    THRESHOLD,
    Selection,
    Step,
    Tested,
    best_with,
    final_indices,
    step_positions,
)
from trainer.physics.effects import EffectConfig

MAX_ALTERNATIVES = 4  # confounders tried singly, and in pairs (6)


def prefer_plausible(
    selection: Selection,
    data: BlockData,
    identifiable: set[str],
    implausible: Callable[[ModelFit, int], bool],
) -> Selection | None:
    """The selection with its first implausible term replaced by the plausible confounder that fits
    lowest in BIC in its place, when that is lower than the search's model; ``None`` when there is none.

    Only the term's declared confounders (what the ambiguity step would list), not yet in the model,
    each with its own ML noise (as :func:`resolve_implausible` fits them); the replacement's own
    parameters must be plausible. The caller re-runs the importance and ambiguity step on the result.
    """
    final = selection.final
    for (effect, occurrence), index in final_indices(selection).items():
        if index is None or not implausible(final, index) or (effect, occurrence) not in selection.drop_one:
            continue
        reduced = selection.drop_one[(effect, occurrence)][1]
        names = [
            a
            for a in CONFUSABLE.get(effect, ())
            if a in identifiable and a not in NOISE_EFFECTS and a not in final.identifiers
        ]
        fits = [(a, fit) for a in names if (fit := best_with(reduced, data, a)) is not None]
        better = [
            (a, fit) for a, fit in fits if fit.bic < final.bic and not implausible(fit, len(fit.terms) - 1)
        ]
        if not better:
            continue
        name, fit = min(better, key=lambda item: item[1].bic)
        gain = final.bic - fit.bic
        seen: dict[str, int] = {}
        steps: list[Step] = []
        for step in selection.steps:
            count = seen.get(step.effect, 0)
            seen[step.effect] = count + 1
            if (step.effect, count) != (effect, occurrence):
                steps.append(replace(step))
        earned = reduced.bic - fit.bic
        steps.append(
            Step(
                name,
                fit,
                earned,
                f"BIC improvement {earned:.1f} (GLS, noise re-estimated by ML), in the place of an "
                f"implausible {effect} whose model it fits {gain:.1f} lower in BIC",
                len(fit.terms) - 1,
            )
        )
        for step, position in zip(steps, step_positions(steps, fit), strict=True):
            step.term_index = position
        replaced = Tested(
            effect,
            -gain,
            f"replaced: its best fit is implausible and {name} fitted in its place gives a BIC lower by {gain:.1f}",
        )
        return Selection(steps, fit, fit, [*selection.tested_first_round, replaced], selection.reference)
    return None


def _added_flags(fit: ModelFit, base: ModelFit, flags: Callable[[EffectConfig], list[str]]) -> list[str]:
    """The plausibility flags of the effects ``fit`` has beyond ``base``."""
    old = len(catalogue_effects(base))
    return [f"{e.identifier}: {text}" for e in catalogue_effects(fit)[old:] for text in flags(e)]


def resolve_implausible(
    selection: Selection,
    data: BlockData,
    identifiable: set[str],
    left_out: Sequence[LeftOut],
    flags: Callable[[EffectConfig], list[str]],
) -> tuple[list[LeftOut], list[Ambiguity]]:
    """(left-out effects still named, new ambiguities) after checking every named effect's plausibility."""
    final = selection.final
    kept = list(left_out)
    ambiguities = []
    seen: dict[str, int] = {}
    for step in selection.steps:
        occurrence = seen.get(step.effect, 0)
        seen[step.effect] = occurrence + 1
        entry = next(
            (e for e in kept if e.effect == step.effect and e.flags and e.peak_visible_mg is not None), None
        )
        index = final_indices(selection).get((step.effect, occurrence))
        if entry is None or index is None or (step.effect, occurrence) not in selection.drop_one:
            continue
        reduced = selection.drop_one[(step.effect, occurrence)][1]
        # Its confounders, then theirs (a creep on a cycle also passes for a hysteresis through a lag).
        direct = CONFUSABLE.get(step.effect, ())
        around = [c for a in direct for c in CONFUSABLE.get(a, ())]
        names = [
            a
            for a in dict.fromkeys([*direct, *around])
            if a != step.effect
            and a in identifiable
            and a not in final.identifiers
            and a not in NOISE_EFFECTS
        ][:MAX_ALTERNATIVES]
        if not names:  # nothing plausible to compare it with: it stays named, with its flags
            continue
        singles = {a: best_with(reduced, data, a) for a in names}
        alternatives = []
        for a, fit in singles.items():
            if fit is not None:
                alternatives.append(Alternative((a,), fit.bic - final.bic, _added_flags(fit, reduced, flags)))
        for a, b in combinations(names, 2):
            first = singles[a]
            pair = None if first is None else best_with(first, data, b)
            if pair is not None:
                alternatives.append(
                    Alternative((a, b), pair.bic - final.bic, _added_flags(pair, reduced, flags))
                )
        alternatives.sort(key=lambda alt: alt.delta_bic)
        plausible = [alt for alt in alternatives if not alt.flags]
        best = plausible[0] if plausible else None
        separations = [
            SEPARATING_SIGNATURE[key]
            for a in names
            if (key := frozenset({step.effect, a})) in SEPARATING_SIGNATURE
        ]
        listed = "; ".join(
            f"{' + '.join(alt.effects)} {alt.delta_bic:+.1f}" + (" (implausible too)" if alt.flags else "")
            for alt in alternatives
        )
        reason = (
            f"the shape the search chose, {step.effect}, is implausible ({'; '.join(entry.flags)}); "
            f"fitted in its place (BIC difference from it): {listed or 'nothing fits'}"
            + (f"; what would separate them: {'; '.join(separations)}" if separations else "")
        )
        if best is None or best.delta_bic >= THRESHOLD:
            reason += (
                "; no plausible alternative comes close: the residual's shape is real, its physics unsettled"
            )
        ambiguities.append(
            Ambiguity(
                (step.effect, *names),
                best.delta_bic if best else float("nan"),
                " + ".join(best.effects) if best else "",
                reason,
                alternatives=tuple(alternatives),
                implausible=entry,
            )
        )
        kept.remove(entry)
    return kept, ambiguities
