"""The finder's verdict per effect, in the words both ``trainer diagnose`` and ``trainer fit
--method physics`` print: which fitted effects it does not accept as physics (a parameter outside
the plausible range, :mod:`trainer.physics.catalogue.plausibility`), and its ambiguities.

The physics fit takes this verdict over unchanged (it never compensates an effect the finder
calls implausible), so the two commands tell one story on the same recording.
"""

from __future__ import annotations

from trainer.diagnose.result import Ambiguity, Diagnosis
from trainer.physics.catalogue.units import CATALOGUE_UNIT, channel_param_name

SHOWN_ALTERNATIVES = 3  # plausible stand-ins printed per implausible best fit


def implausible_effects(d: Diagnosis) -> dict[str, str]:
    """``{effect: why}`` for every effect the finder fitted with a parameter outside its plausible
    range: an implausible best fit (reported as ambiguous) or a named effect with its flags."""
    out = {a.effects[0]: "; ".join(a.implausible.flags) for a in d.ambiguous if a.implausible is not None}
    out.update({e.effect: "; ".join(e.flags) for e in d.left_out if e.flags})
    return out


def moves_text(a: Ambiguity, unit: str = CATALOGUE_UNIT) -> str:
    """What moves when an absorbed confounder is fitted beside the model ("" when nothing does):
    the named values it would take part of, in the channel's parameter names (``unit``)."""
    if not a.moves:
        return ""
    moved = ", ".join(
        f"{effect}.{channel_param_name(name, unit)} {value:.4g} -> {beside:.4g} ({100 * (beside - value) / abs(value):+.0f} %)"
        for effect, name, value, beside in a.moves
    )
    return (
        f"; fitted beside, {a.effects[1]} moves {moved}: these values may carry part of a "
        f"{a.effects[1]} in the data"
    )


def ambiguity_line(a: Ambiguity, label: str = "", unit: str = CATALOGUE_UNIT) -> str:
    """One line for an ambiguity (``label``: the channel and unit on a non-mg channel; ``unit``: its
    parameters' unit suffix)."""
    if a.undetermined:
        effect, other = a.effects
        return (
            f"undetermined: {other}{label} beside {effect} on this profile (beside the model BIC "
            f"{a.delta_bic:+.1f}, in its place too little to name: this run cannot tell whether one is "
            f"present{moves_text(a, unit)})"
        )
    if a.absorbed:
        effect, other = a.effects
        return (
            f"absorbed: {'another ' if a.another else ''}{other}{label} by {effect} on this profile (in its place BIC {a.delta_bic:+.1f}, beside it "
            f"too little to name: a real one would be merged into the fitted term{moves_text(a, unit)})"
        )
    if a.implausible is None:
        return f"ambiguous: {' vs '.join(a.effects)}{label} (BIC {a.delta_bic:+.1f})"
    shown = [f"{' + '.join(alt.effects)} {alt.delta_bic:+.1f}" for alt in a.alternatives if not alt.flags]
    return (
        f"ambiguous (not named): {a.effects[0]}{label}, the search's choice, fits implausibly "
        f"({'; '.join(a.implausible.flags)}); plausible in its place, BIC: "
        f"{', '.join(shown[:SHOWN_ALTERNATIVES]) or 'none'}"
    )
