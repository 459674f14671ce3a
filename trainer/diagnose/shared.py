"""Which effect in the model a near miss shares its signature with: confounding said out loud.

A candidate that earns less than the criterion beside the final model is either weak (a longer or
quieter run would name it) or confounded: an effect in the model explains the same part of the
run, and without that effect the candidate would pass. The remedies differ (more data against a
profile that separates the two), so the report says which. Measured on the bundled real run with a
filtered rate term added to accel x at twice its detection limit: the run's own step just after the
cold reversal earns 8.8 beside the final model; without its weak hysteresis (0.031 mg) it earns 20.4,
and in the hysteresis's place it fits only 5.8 worse in BIC. Without the rate term it earns 10.8, still
below the criterion: the hysteresis, not the added rate term, is what it is confounded with
(docs/diagnose.md).
"""

from __future__ import annotations

from dataclasses import dataclass

from trainer.diagnose.model import ModelFit, fit_model
from trainer.diagnose.select import THRESHOLD
from trainer.physics.catalogue import BACKBONE


@dataclass(frozen=True)
class SharedSignature:
    """An effect of the model without which a near miss would pass the criterion."""

    effect: str
    delta_bic: float  # BIC drop the near miss earns once this effect is out of the model
    in_place_bic: float  # BIC of the model with the near miss in this effect's place, minus the final's


def shared_signatures(final: ModelFit, miss_fit: ModelFit) -> tuple[SharedSignature, ...]:
    """The effects of ``final`` (the bias polynomial aside) each of which, once dropped, lets the near
    miss's terms (the last terms of ``miss_fit``, fitted beside ``final``) earn the criterion or more;
    strongest first. Both sides are refitted as the finder fits, at the final model's noise terms."""
    n_final = len(final.terms)
    model, added = miss_fit.terms[:n_final], miss_fit.terms[n_final:]
    noise, data = final.noise.terms, final.data
    out = []
    for index, term in enumerate(model):
        if term.identifier == BACKBONE:
            continue
        others = tuple(t for k, t in enumerate(model) if k != index)
        without = fit_model(others, noise, data, start=final.noise)
        with_it = fit_model(others + added, noise, data, start=final.noise)
        evidence = without.bic - with_it.bic
        if evidence >= THRESHOLD:
            out.append(SharedSignature(term.identifier, evidence, with_it.bic - final.bic))
    return tuple(sorted(out, key=lambda s: -s.delta_bic))


def shared_text(shares: tuple[SharedSignature, ...]) -> str:
    """The report's words for ``shares`` (empty when the near miss is merely weak)."""
    return "; ".join(_one(s) for s in shares)


def _one(s: SharedSignature) -> str:
    gap = s.in_place_bic
    if gap >= THRESHOLD:
        which = f"the model with {s.effect} fits better by {gap:.1f} in BIC"
    elif gap >= 0:
        which = (
            f"the model with {s.effect} fits better by only {gap:.1f} in BIC, less than the criterion: "
            "either may explain this part of the run"
        )
    else:
        which = f"the near miss in its place fits better by {-gap:.1f} in BIC"
    return (
        f"without {s.effect} it earns {s.delta_bic:.1f}, above the criterion: it shares its signature "
        f"with {s.effect} on this run ({which})"
    )
