"""The user's simulation as the starting model: which terms, their starting values, the known input.

Every effect of the configuration becomes a model term whose free parameters are calibrated to
the recording; the configuration's values are only starting points. Without a configuration the
baseline is ``bias_poly`` plus the default noise terms (white noise, bias instability, rate random
walk), as in ``trainer/physics/default.toml``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from trainer.diagnose.model import Term
from trainer.physics.catalogue import BACKBONE, COVARIANCE_NOISE, DEFINITIONS, NOISE, WHITE_NOISE
from trainer.physics.catalogue.base import StartContext, starting_term
from trainer.physics.config import PhysicsConfig, input_setters
from trainer.physics.inputs import input_signal

DEFAULT_NOISE = COVARIANCE_NOISE
BLOCK_NOISE = COVARIANCE_NOISE


@dataclass
class Baseline:
    terms: tuple[Term, ...]
    noise_terms: tuple[str, ...]
    identifiers: list[str]  # effects and noise terms of the starting model, for the report
    known_input: np.ndarray | None
    input_varies: bool
    notes: list[str] = field(default_factory=list)


def known_input(cfg: PhysicsConfig, t: np.ndarray) -> np.ndarray | None:
    """The deterministic true input the configuration declares (Singer manoeuvres are unknown)."""
    given = [effect.params[name] for effect, name in input_setters(cfg.effects)]
    if given:
        return np.full(t.size, float(given[0]))
    if cfg.input.kind == "zero":
        return None
    deterministic = replace(cfg.input, singer_sigma_mg=0.0)
    return input_signal(deterministic, t, np.random.default_rng(0))


def build_baseline(cfg: PhysicsConfig | None, t: np.ndarray, lattice_lsb_c: float | None) -> Baseline:
    """Terms and noise of the starting model (``t``: the recording's time axis from 0)."""
    if cfg is None:
        return Baseline(
            terms=(Term(BACKBONE),),
            noise_terms=DEFAULT_NOISE,
            identifiers=[BACKBONE, WHITE_NOISE, *DEFAULT_NOISE],
            known_input=None,
            input_varies=False,
            notes=[
                "no --sim given: baseline is bias_poly plus white noise, bias instability, rate random walk"
            ],
        )
    notes: list[str] = []
    g_in = known_input(cfg, t)
    varies = bool(g_in is not None and np.ptp(g_in) > 1.0)
    # The finder's models always start from the backbone (bias_poly), whatever the simulation says.
    terms: list[Term] = [Term(BACKBONE)]
    identifiers = [BACKBONE]
    if not cfg.effect_instances(BACKBONE):
        notes.append(f"the simulation has no {BACKBONE}; the finder always fits one (the drift's backbone)")
    context = StartContext(lattice_lsb_c, varies)
    for effect in cfg.effects:
        definition = DEFINITIONS[effect.identifier]
        if definition.finder.backbone:
            continue
        identifiers.append(effect.identifier)
        start = starting_term(definition, effect.params, context)
        terms.append(Term(effect.identifier, start.nl, fixed=start.fixed))
        if start.note:
            notes.append(start.note)
    noise = []
    for term in cfg.noise:
        identifiers.append(term.identifier)
        finder = DEFINITIONS[term.identifier].finder
        if finder.noise_role == "covariance":
            noise.append(term.identifier)
        elif finder.noise_role == "trend":  # a deterministic trend (rate_ramp) is a model term
            start = starting_term(DEFINITIONS[term.identifier], term.params, context)
            terms.append(Term(term.identifier, start.nl, fixed=start.fixed))
        elif finder.config_note:
            notes.append(finder.config_note)
    if WHITE_NOISE not in identifiers:
        notes.append(NOISE[WHITE_NOISE].finder.missing_note)
    order = [t for t in BLOCK_NOISE if t in noise]
    return Baseline(tuple(terms), tuple(order), identifiers, g_in, varies, notes)
