"""What the user should do next: the compensator the findings call for, what it will leave per
branch, and the chamber profile that would settle what remains ambiguous (report and terminal)."""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from trainer.data.channels import SECOND_INPUT, UNIT_LABELS
from trainer.diagnose.fit_summary import rms
from trainer.diagnose.profile import BRANCH_NAMES, Profile
from trainer.diagnose.result import Diagnosis
from trainer.diagnose.select import THRESHOLD
from trainer.physics.catalogue import BACKBONE, EFFECTS, SEPARATING_SIGNATURE
from trainer.scoring.markdown import markdown_table

COMPENSATOR = "physics compensator (`trainer fit --method physics`, which keeps a term only when cross-validation confirms it)"


HOLD_AFTER_RAMP_S = 3600.0  # a hold this long after a ramp lets a lag, a rate term and a relaxation settle


def generic_profile(unit: str, profile: Profile | None = None) -> str:
    """The profile that separates the catalogue's effects on any channel (``unit``: as printed, deg/s),
    its second input the channel's own; given the run's ``profile``, only what the run lacks (a run
    with 1.5 h holds was told to add holds of >= 1 h)."""
    suffix = next((k for k, label in UNIT_LABELS.items() if label == unit), None)
    second = SECOND_INPUT.get(suffix or "", "; ".join(SECOND_INPUT.values()))
    wanted = [
        ("holds of >= 1 h after a ramp", profile is None or profile.holds_after_ramp_s < HOLD_AFTER_RAMP_S),
        ("two ramp rates", profile is None or len(profile.ramp_rates) < 2),
        ("a heating/cooling reversal", profile is None or profile.reversals < 1),
        (
            f"a known second input at two temperatures ({second})",
            profile is None or not profile.known_input_varies,
        ),
    ]
    missing = [text for text, lacking in wanted if lacking]
    if profile is not None and len(missing) < len(wanted):
        had = [text.split(" (")[0] for text, lacking in wanted if not lacking]
        if not missing:
            return f"this run already has {', '.join(had)}: a second run of the same profile"
        return f"{', '.join(missing)} (this run already has {', '.join(had)})"
    return ", ".join(missing[:-1]) + " and " + missing[-1]


@dataclass(frozen=True)
class BranchResidual:
    branch: str  # heating, cooling, hold
    blocks: int
    before_mg: float  # block RMS of the starting model's residual on this branch
    after_mg: float  # ... of the final model's least-squares fit (what a compensator would leave)


@dataclass(frozen=True)
class NextSteps:
    structure: str
    not_compensated: list[str]  # named events and set-up effects: to check, not to compensate
    branches: list[BranchResidual]
    profile: list[str]  # tests, most specific first; the generic profile last
    unit: str = "mg"  # the diagnosed channel's unit as printed (the residuals are in it)
    # terms the final fit holds that the compensator does not carry (events, set-up effects, a term
    # fitted implausibly): the "after" figures include them, so a compensator leaves more where they act
    fit_only: list[str] = field(default_factory=list)

    def after_text(self) -> str:
        """What the per-branch "after" figure is, said where it is shown."""
        if not self.fit_only:
            return "what the compensator would leave"
        return (
            f"the finder's whole model, {', '.join(self.fit_only)} included, which the compensator does not "
            "carry: it leaves more where they act"
        )


def compensable(identifier: str) -> bool:
    """Whether a finding belongs in a temperature compensator: a catalogue effect marked so, not an
    event or set-up effect, nor a noise term's trend in time (``rate_ramp``, a slow wander of the run)."""
    effect = EFFECTS.get(identifier)
    return effect is not None and effect.compensable


def next_steps(d: Diagnosis) -> NextSteps:
    named = [e.effect for e in d.left_out if e.peak_visible_mg is not None]
    # the --sim's own compensable effects the recording supports, calibrated plausibly, are terms too
    # (with a simulation that already holds them the advice said the bias polynomial alone)
    unsupported = {n.effect for n in d.not_supported} | {e.identifier for e, _ in d.implausible_baseline()}
    simulated = [
        e.identifier
        for e in d.baseline_effects
        if compensable(e.identifier) and e.identifier not in unsupported and e.identifier not in named
    ]
    compensated = list(dict.fromkeys([*simulated, *(e for e in named if compensable(e))]))
    lagged = any(EFFECTS[e].proof_mass is not None for e in compensated)
    temperature = "the lagged (proof-mass) temperature" if lagged else "the die temperature"
    terms = [f"{BACKBONE} (bias polynomial) in {temperature}", *compensated]
    choices = [a for a in d.ambiguous if a.implausible is not None]
    for a in choices:
        assert a.implausible is not None
        earned = a.implausible.evidence.delta_bic_when_dropped - THRESHOLD  # beats leaving it out
        options = [
            " + ".join(alt.effects) for alt in a.alternatives if not alt.flags and alt.delta_bic < earned
        ]
        if options:
            terms.append(f"one of {' | '.join(options)} (in place of the implausible {a.effects[0]})")
        else:
            terms.append(
                f"an open term where {a.effects[0]} fits implausibly (settle it with the profile below)"
            )
    alternatives: dict[str, list[str]] = {}
    for a in d.ambiguous:
        # an absorbed confounder fits worse, an undetermined one earns too little: no alternative
        if a.implausible is None and not a.absorbed and not a.undetermined:
            alternatives.setdefault(a.preferred, []).extend(e for e in a.effects if e != a.preferred)
    for preferred, others in alternatives.items():
        either = f"{preferred} (or {' / '.join(dict.fromkeys(others))})"
        if preferred in terms:  # a named effect: one term, with its alternatives
            terms[terms.index(preferred)] = either
        else:
            terms.append(either)
    structure = f"{COMPENSATOR}: " + " + ".join(terms)

    # The least-squares residuals of the summaries (a GLS fit under a strong random walk pins the
    # level loosely); the after fit is what a compensator with these terms would leave.
    before, after = d.before.residual_block, d.after.residual_block
    branches = []
    for code, name in BRANCH_NAMES.items():
        mask = np.asarray(d.profile.branch) == code
        if mask.any():
            branches.append(BranchResidual(name, int(mask.sum()), rms(before[mask]), rms(after[mask])))

    profile: list[str] = []
    for a in d.ambiguous:
        for pair in combinations(a.effects, 2):
            if text := SEPARATING_SIGNATURE.get(frozenset(pair)):
                profile.append(f"{pair[0]} vs {pair[1]}: {text}")
    unsettled = {e for a in d.ambiguous for e in a.effects} | {n.effect for n in d.not_identifiable}
    for effect, info in d.profile.identifiability.items():
        if info.test and (effect in unsettled or info.weak) and (not info.identifiable or info.weak):
            profile.append(f"{effect}: {info.test}")
    profile.append(generic_profile(d.signal.label, d.profile))
    not_compensated = list(dict.fromkeys(e for e in named if not compensable(e)))
    implausible = [a.effects[0] for a in d.ambiguous if a.implausible is not None]
    fit_only = list(dict.fromkeys([*not_compensated, *(f"{e} (implausible)" for e in implausible)]))
    return NextSteps(
        structure, not_compensated, branches, list(dict.fromkeys(profile)), d.signal.label, fit_only
    )


def markdown_lines(steps: NextSteps) -> list[str]:
    lines = ["## What to do next", "", f"Compensator: {steps.structure}.", ""]
    if steps.not_compensated:
        lines += [
            f"Not for the compensator (events, the test set-up or a slow trend in time; check the recording and the rig): "
            f"{', '.join(steps.not_compensated)}.",
            "",
        ]
    if steps.branches:
        lines += [
            f"Residual per branch (block RMS, {steps.unit}), starting model -> after the fit ({steps.after_text()}):",
            "",
            markdown_table(
                ["branch", "blocks", "before", "after"],
                [
                    [b.branch, str(b.blocks), f"{b.before_mg:.3f}", f"{b.after_mg:.3f}"]
                    for b in steps.branches
                ],
                align="lrrr",
            ),
            "",
        ]
    lines += ["Next chamber profile, to settle what remains ambiguous:", ""]
    lines += [f"- {p}" for p in steps.profile]
    return lines


def terminal_lines(steps: NextSteps) -> list[str]:
    per_branch = ", ".join(f"{b.branch} {b.before_mg:.3g} -> {b.after_mg:.3g}" for b in steps.branches)
    check = (
        [
            f"next: not for the compensator (events, the test set-up or a trend in time): {', '.join(steps.not_compensated)}"
        ]
        if steps.not_compensated
        else []
    )
    return [
        f"next: {steps.structure}",
        *check,
        f"next: residual per branch (block RMS, {steps.unit}) {per_branch}"
        + (f" (after: {steps.after_text()})" if steps.fit_only else "")
        + f"; next profile: {steps.profile[0]}"
        + (f" (+{len(steps.profile) - 1} more in the report)" if len(steps.profile) > 1 else ""),
    ]
