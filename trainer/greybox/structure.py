"""The compensator's structure: which catalogue effects, and where their starting values come from.

Three sources, one result (:class:`Structure`):

* ``auto``: the mismatch finder on the training recording (no ``--sim``). It adds an effect only
  when the temperature profile can identify it and the BIC asks for it, so a monotone ramp or a
  warm-up gives the bias polynomial alone.
* a forced list (``--effects thermal_lag,temp_rate``): each is profiled against the model so far.
* ``--from-sim augmented.toml`` (what ``trainer diagnose --report`` writes): its effects and values.

Found effects that are not sensor drift (a step, a chamber oscillation, a quantised thermometer)
stay in the fit as nuisance terms, so they do not bias the parameters, and are not compensated;
except one the profile identifies only weakly (a warm-up on a run with no soak at power-on): it
trades off with the compensated terms, and fitted beside them it takes drift the compensator must
remove (the bundled run's gyro z: a 0.40 deg/s warm-up beside a 0.099 deg/s branch offset, which
left 0.104 deg/s on the first cooling against 0.093 uncompensated; without it 0.051).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from trainer.data.channels import channel_unit
from trainer.data.recording import Recording
from trainer.errors import UserError
from trainer.greybox.terms import compensated
from trainer.physics.catalogue import BACKBONE, EFFECTS
from trainer.physics.config import load_config
from trainer.physics.effects import EffectConfig


@dataclass(frozen=True)
class Structure:
    """Effects to compensate and nuisance effects to fit, each with starting parameters (``{}``:
    none, profile it), how the choice was made, and what the finder said could not be decided."""

    compensated: tuple[EffectConfig, ...]
    nuisance: tuple[EffectConfig, ...] = ()
    how: str = ""
    notes: tuple[str, ...] = field(default_factory=tuple)
    # compensable effects the profile identifies but the finder did not name (auto only): the
    # cross-validated stage (:mod:`trainer.greybox.select`) may still add them
    candidates: tuple[str, ...] = ()
    # effects the finder fitted implausibly (auto only), with its reason: never compensated
    rejected: tuple[tuple[str, str], ...] = ()
    # effects the fit dropped as undetermined by the run (auto only), with the reason
    dropped: tuple[tuple[str, str], ...] = ()


def forced(names: tuple[str, ...], given_by: str = "--effects") -> Structure:
    """The effects ``names``, as given by ``given_by`` (the option, or auto's candidate that fixes them)."""
    listed = ",".join(names) or "none"
    how = f"forced: {given_by} {listed}" if given_by.startswith("--") else f"forced: {listed} ({given_by})"
    return Structure(tuple(EffectConfig(n, {}) for n in names), how=how)


def _split(effects: list[EffectConfig], warmup_allowed: bool) -> tuple[tuple[EffectConfig, ...], ...]:
    comp = tuple(e for e in effects if compensated(e.identifier, warmup_allowed=warmup_allowed))
    nuisance = tuple(e for e in effects if e not in comp and EFFECTS[e.identifier].contribution is not None)
    return comp, nuisance


def from_sim(path: Path, rec: Recording, *, warmup_allowed: bool) -> Structure:
    """The effects of an augmented simulation (``trainer diagnose --report``), as starting values
    (a gyroscope's or barometer's from its ``[channels.<name>]`` table)."""
    cfg = load_config(path).for_channel(rec.meta.get("channel"), channel_unit(rec))
    effects = [e for e in cfg.effects if e.identifier != BACKBONE]
    comp, nuisance = _split(effects, warmup_allowed)
    return Structure(comp, nuisance, how=f"from {path.name}")


def auto(rec: Recording, *, warmup_allowed: bool, progress: bool = False) -> Structure:
    """What the mismatch finder names on the training recording itself (no user simulation)."""
    from trainer.diagnose.api import ambiguity_line, diagnose, implausible_effects  # heavy: on use

    diagnosis = diagnose(rec, None, holdout_fraction=0.0, progress=progress, report_search=False)
    rejected = implausible_effects(diagnosis)
    found = [
        EffectConfig(e.effect, dict(e.params))
        for e in diagnosis.left_out
        if e.effect in EFFECTS and not (e.flags and compensated(e.effect, warmup_allowed=warmup_allowed))
    ]
    comp, nuisance = _split(found, warmup_allowed)
    # the finder's own lines (as `trainer diagnose` prints them): the fit adds its decisions after them
    notes = [f"finder: {ambiguity_line(a, diagnosis.label, diagnosis.unit)}" for a in diagnosis.ambiguous]
    identifiability = diagnosis.profile.identifiability
    weak = {
        e.identifier: identifiability[e.identifier].reason
        for e in nuisance
        if e.identifier in identifiability and identifiability[e.identifier].weak
    }
    nuisance = tuple(e for e in nuisance if e.identifier not in weak)
    notes += [
        f"finder: {name} not fitted beside the compensator: weakly identifiable on this profile ({reason}), "
        "it would take drift the compensator must remove from power-on"
        for name, reason in sorted(weak.items())
    ]
    notes += [
        f"finder: not identifiable from this profile: {n.effect} ({n.reason}); to identify it: {n.recommended_test}"
        for n in diagnosis.not_identifiable
        if compensated(n.effect, warmup_allowed=True)
    ]
    named = ", ".join(e.identifier for e in comp) or "nothing beyond the bias polynomial"
    present = {e.identifier for e in found}
    candidates = tuple(
        name
        for name, info in diagnosis.profile.identifiability.items()
        if info.identifiable and name not in present and compensated(name, warmup_allowed=warmup_allowed)
    )
    return Structure(
        comp,
        nuisance,
        how=f"auto: the finder named {named}",
        notes=tuple(notes),
        candidates=candidates,
        rejected=tuple(rejected.items()),
    )


def check_source(effects: str | None, from_sim_path: str | None) -> None:
    if effects not in (None, "auto") and from_sim_path is not None:
        raise UserError("--effects and --from-sim both give the structure; give one")
