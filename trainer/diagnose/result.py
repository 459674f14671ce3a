"""What a diagnosis found, as typed values (unrounded; :mod:`.document` writes the ``--json`` form)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from trainer.data.channels import ONE_AXIS_CHANNEL, UNIT_LABELS, Signal
from trainer.diagnose.baseline import Baseline
from trainer.diagnose.blocks import BlockData
from trainer.diagnose.detection import DetectionLimit
from trainer.diagnose.fit_summary import FitSummary
from trainer.diagnose.holdout import Holdout
from trainer.diagnose.model import ModelFit
from trainer.diagnose.profile import Profile, Region
from trainer.diagnose.select import Selection
from trainer.diagnose.shared import SharedSignature
from trainer.diagnose.where import AllanWhere
from trainer.physics.catalogue.units import CATALOGUE_UNIT, ChannelScale, channel_params
from trainer.physics.config import PhysicsConfig
from trainer.physics.effects import EffectConfig


@dataclass(frozen=True)
class Evidence:
    """The BIC evidence for a left-out effect (the criterion is always the BIC)."""

    delta_bic_when_added: float
    delta_bic_when_dropped: float  # from the final model: the effect's importance
    how: str  # how the candidate was found (grid, spectral peak, ...)


@dataclass(frozen=True)
class LeftOut:
    """An effect (or noise term) the user's simulation leaves out, with its fitted parameters."""

    effect: str
    params: dict[str, float]
    where: list[Region | AllanWhere]
    evidence: Evidence
    advice: str
    peak_visible_mg: float | None = None  # None for noise terms
    flags: list[str] = field(default_factory=list)  # parameters outside the plausible range
    ambiguous_with: list[str] = field(default_factory=list)  # as good a description, within the BIC tie
    # confounders this effect would absorb on this profile (one present would be merged into its fitted
    # term): not as good a description, so not "could also be"
    absorbs: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Alternative:
    """A plausible stand-in (one effect or a pair) for an implausible best fit, and its BIC cost."""

    effects: tuple[str, ...]
    delta_bic: float  # BIC of the model with it minus that with the implausible best fit
    flags: list[str] = field(default_factory=list)  # its own implausible parameters, if any


@dataclass(frozen=True)
class Ambiguity:
    """Effects the data cannot tell apart (swapping one for the other costs little BIC), or an
    implausible best fit (``implausible``) and the plausible ``alternatives`` fitted in its place."""

    effects: tuple[str, ...]
    delta_bic: float
    preferred: str
    reason: str
    alternatives: tuple[Alternative, ...] = ()
    # the shape the search chose, with its flags; not named (a pair may fit lower, implausibly too)
    implausible: LeftOut | None = None
    # effects[1]'s signature is absorbed by effects[0] on this profile: in its place it fits worse by
    # delta_bic, beside it it earns too little (trainer.diagnose.select, step 4), not a tie
    absorbed: bool = False
    # absorbed or undetermined: (effect, parameter, value, value with effects[1] fitted beside) for each
    # named parameter that moves by more than select.MOVED_FRACTION: it is not determined apart from it
    moves: tuple[tuple[str, str, float, float], ...] = ()
    # absorbed only: the model already names an instance of effects[1] (a multi-instance effect): the
    # absorbed one is a further instance
    another: bool = False
    # effects[1] earns too little both in a named effect's place and beside the model (this run cannot
    # determine it), yet fitted beside the model it moves named values (``moves``); delta_bic is its
    # BIC change beside the model. Not a tie, not an alternative for the compensator
    undetermined: bool = False


@dataclass(frozen=True)
class Suggestive:
    """A candidate below the criterion beside the final model, but with strong evidence (a near
    miss, :func:`trainer.diagnose.select.near_misses`): listed, not named, not in the compensator."""

    effect: str
    params: dict[str, float]
    delta_bic: float  # BIC drop when added to the final model
    flags: list[str] = field(default_factory=list)  # parameters outside the plausible range
    joint: int = 1  # instances listed together that share this evidence (a pair of steps: 2)
    # effects of the model without which it would pass the criterion (:mod:`trainer.diagnose.shared`)
    shares: tuple[SharedSignature, ...] = ()


@dataclass(frozen=True)
class NotIdentifiable:
    effect: str
    reason: str
    recommended_test: str


@dataclass(frozen=True)
class NotSupported:
    """An effect of the user's simulation that the data do not need (dropping it lowers the BIC)."""

    effect: str
    delta_bic: float
    reason: str


@dataclass(frozen=True)
class Tested:
    """A candidate scored in the first round (``delta_bic``, ``how``) or only noted (``note``)."""

    effect: str
    delta_bic: float | None = None
    how: str = ""
    note: str = ""


@dataclass
class Diagnosis:
    """Everything the report needs; :func:`trainer.diagnose.document.document` is the ``--json`` form."""

    source: str
    data: BlockData
    profile: Profile
    baseline: Baseline
    baseline_fit: ModelFit
    baseline_effects: list[EffectConfig]  # the user's effects as calibrated
    selection: Selection
    left_out: list[LeftOut]
    ambiguous: list[Ambiguity]
    not_identifiable: list[NotIdentifiable]
    undetected: list[DetectionLimit]  # weakly identifiable, not named: the smallest size named
    not_supported: list[NotSupported]
    mismatch: list[Region]
    unexplained: list[Region]
    before: FitSummary
    after: FitSummary
    tested: list[Tested]
    augmented: PhysicsConfig
    holdout: Holdout | None
    seconds: float
    notes: list[str] = field(default_factory=list)
    suggestive: list[Suggestive] = field(default_factory=list)  # near misses, strongest first
    channel: str | None = None  # the channel of a one-channel view (None: a one-axis recording)
    unit: str = "mg"  # the unit suffix of the recording's values (mg, dps, pa): names every amplitude
    scale: ChannelScale | None = None  # what a non-mg channel's amplitudes were judged against

    def implausible_baseline(self) -> list[tuple[EffectConfig, list[str]]]:
        """The effects of the user's simulation (``--sim``) whose calibrated parameters (JSON
        ``baseline_calibrated``) are outside the plausible range, each with its reasons: the rule the
        finder applies to what it names (:func:`trainer.physics.catalogue.plausibility.implausible`)."""
        from trainer.physics.catalogue.plausibility import implausible

        out = []
        for effect in self.baseline_effects:
            if flags := list(implausible(effect.identifier, effect.params, self.scale).values()):
                out.append((effect, flags))
        return out

    def params(self, values: Mapping[str, float]) -> dict[str, float]:
        """Catalogue-named parameters as this channel names them (``amp_mg`` -> ``amp_dps``)."""
        return channel_params(values, self.unit)

    @property
    def signal(self) -> Signal:
        """The diagnosed channel and its unit, as figures and tables name them."""
        return Signal(self.channel or ONE_AXIS_CHANNEL, self.unit)

    @property
    def label(self) -> str:
        """`` [gyro0_x, deg/s]``: what a report prints beside every finding on a non-mg channel
        (empty on mg, whose reports stay as they were: the catalogue's own unit)."""
        if self.unit == CATALOGUE_UNIT:
            return ""
        return f" [{self.channel or 'channel'}, {UNIT_LABELS[self.unit]}]"
