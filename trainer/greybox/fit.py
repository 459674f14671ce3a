"""Joint fit of a structure with the mismatch finder's model (block means, GLS, noise by ML).

The finder's machinery does the work: the same design columns, the same profile search for a
term without starting values, the same joint polish of every nonlinear parameter with the bias
polynomial refitted at each step (:func:`trainer.diagnose.model.fit_model`). Two things are
specific to a compensator:

* the linear coefficients are refitted by least squares at the fitted nonlinear values: the
  compensator runs with no noise model in the field, which is what the finder's held-out figure
  scores too (``trainer.diagnose.holdout.HEADLINE``);
* a term whose streamed form needs a filter (:attr:`StreamedEffect.min_filter_s`, the rate term)
  has its time constant searched from at least that: firmware cannot differentiate a noisy,
  quantised thermometer reading without one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from trainer.data.channels import channel_unit
from trainer.data.recording import Recording
from trainer.diagnose.api import (
    BlockData,
    Design,
    ModelFit,
    Term,
    analyse_profile,
    build_baseline,
    build_blocks,
    build_design,
    channel_scale,
    evaluate,
    fit_model,
    propose,
    propose_freed_wide,
    search_bounds,
    single_blas_thread,
)
from trainer.errors import UserError
from trainer.greybox.select import STAGE, extend
from trainer.greybox.structure import Structure
from trainer.physics.catalogue import BACKBONE, DEFINITIONS, EFFECTS
from trainer.physics.catalogue.base import catalogue_params
from trainer.physics.catalogue.plausibility import implausible
from trainer.physics.catalogue.streamed import STREAMED
from trainer.physics.catalogue.units import CATALOGUE_UNIT, ChannelScale, channel_param_name
from trainer.physics.effects import EffectConfig

BOUND_MARGIN = 0.01  # a nonlinear value within 1 % of its search range's end sits at the bound


@dataclass(frozen=True)
class FittedPhysics:
    """Catalogue parameters of the compensated effects (bias polynomial first) and what to trust."""

    effects: tuple[EffectConfig, ...]
    nuisance: tuple[EffectConfig, ...]
    std: dict[str, dict[str, float]]  # one standard deviation per parameter (same units)
    # of the compensated effects only (a nuisance term is not judged: it is fitted, never carried)
    at_bound: tuple[str, ...]  # "effect.param" at an end of the finder's search range
    implausible: tuple[str, ...]  # "effect.param" outside the plausible range (the finder's rule)
    blocks: int
    block_s: float
    structure: Structure  # as finally chosen (auto: after the cross-validated stage)
    notes: tuple[str, ...] = ()
    unit: str = CATALOGUE_UNIT  # the channel's unit suffix: how its parameters are named when shown
    why: dict[str, tuple[str, ...]] = field(default_factory=dict)  # effect -> why it is undetermined


def _start_term(effect: EffectConfig) -> Term | None:
    """A term from catalogue starting values; ``None`` when they are missing (profile it)."""
    definition = DEFINITIONS[effect.identifier]
    names = [name for name, _ in definition.finder.nonlinear]
    if not all(name in effect.params for name in names):
        floor = _min_filter_s(effect.identifier)
        linear = [p.name for p in definition.params if p.name not in names]
        if floor is not None and any(name in effect.params for name in linear):
            return Term(effect.identifier, (floor,))
        return None
    return Term(effect.identifier, tuple(float(effect.params[name]) for name in names))


def _place(current: ModelFit, data: BlockData, effect: EffectConfig) -> ModelFit | None:
    """Add one effect: from its starting values, else by the finder's own search for it; ``None``
    when that search places it nowhere on these blocks."""
    term = _start_term(effect)
    if term is not None:
        return evaluate((*current.terms, term), data, current.gls)
    fits = [
        p.fit_fixed_noise for p in propose(current, data, effect.identifier) if p.fit_fixed_noise is not None
    ]
    return max(fits, key=lambda f: f.loglik) if fits else None


def _add(current: ModelFit, data: BlockData, effect: EffectConfig) -> ModelFit:
    """Add an effect of the structure (given by the user, or named by the finder on this run)."""
    placed = _place(current, data, effect)
    if placed is None:
        raise UserError(f"--effects: the finder cannot place {effect.identifier} on this recording")
    return placed


def add_trial(current: ModelFit, data: BlockData, effect: EffectConfig) -> ModelFit | None:
    """The cross-validated stage's placement of a candidate: the finder's, or, for a filtered term,
    its filter searched over the whole range when that fits better (:func:`propose_freed_wide`);
    the stage then keeps it only if it predicts held-out blocks. ``None``: the finder places it
    nowhere on these blocks (a cross-validation fold's rows, a sparse run), so it is not tried."""
    placed = _place(current, data, effect)
    if placed is None or _start_term(effect) is not None:
        return placed
    wide = [p.fit_fixed_noise for p in propose_freed_wide(current, data, effect.identifier)]
    return max([placed, *(f for f in wide if f is not None)], key=lambda f: f.loglik)


def at_search_bound(term: Term, data: BlockData) -> dict[str, tuple[float, float, float]]:
    """``{nonlinear parameter: (value, search range low, high)}`` for each free one within
    :data:`BOUND_MARGIN` of an end of its search range (the run does not determine it)."""
    if term.fixed:
        return {}
    names = [name for name, _ in DEFINITIONS[term.identifier].finder.nonlinear]
    if not names:
        return {}
    out = {}
    for name, (lo, hi), value in zip(names, search_bounds(term.identifier, data), term.nl, strict=False):
        if value - lo < BOUND_MARGIN * (hi - lo) or hi - value < BOUND_MARGIN * (hi - lo):
            out[name] = (value, lo, hi)
    return out


def _least_squares(design: Design, data: BlockData) -> np.ndarray:
    """Linear coefficients by least squares, as the compensator runs (no noise model), on the
    training blocks (a cross-validation fold's held-out blocks have no weight)."""
    weighted = slice(None) if data.held_out is None else ~data.held_out
    beta, *_ = np.linalg.lstsq(design.X[weighted], (data.accel - design.offset)[weighted], rcond=None)
    return np.asarray(beta)


def _owned(design: Design, values: np.ndarray, index: int) -> dict[str, float]:
    """``{role: value}`` of the design columns that term ``index`` owns."""
    return {role: float(v) for (owner, role), v in zip(design.roles, values, strict=True) if owner == index}


def _undetermined(trial: ModelFit, data: BlockData, identifier: str, scale: ChannelScale | None) -> str:
    """Why the trial's last ``identifier`` term is not determined by the run ("" when it is): a
    nonlinear value at an end of its search range or a parameter outside the plausible range, the
    rule the finished fit applies (:func:`_only_determined` of the compensator drops such a term,
    so the cross-validated stage must not choose it over one that is determined)."""
    index = max(i for i, t in enumerate(trial.terms) if t.identifier == identifier)
    term = trial.terms[index]
    definition = DEFINITIONS[identifier]
    for name, (value, lo, hi) in at_search_bound(term, data).items():
        return f"{name} = {value:.4g} at the end of its search range {lo:g}..{hi:g}"
    design = build_design(trial.terms, data)
    linear = _owned(design, _least_squares(design, data), index)
    outside = implausible(identifier, catalogue_params(definition, term, linear), scale)
    return "; ".join(outside.values())


def _min_filter_s(identifier: str) -> float | None:
    streamed = STREAMED.get(identifier)
    return None if streamed is None else streamed.min_filter_s


def _rate_filter(terms: tuple[Term, ...]) -> tuple[Term, ...]:
    """Every term that needs a filter searched from at least its shortest filter."""
    out = []
    for t in terms:
        floor = _min_filter_s(t.identifier)
        out.append(
            t if floor is None else replace(t, nl=(max(t.nl[0] if t.nl else 0.0, floor),), fixed=False)
        )
    return tuple(out)


def _clamp_rate(fit: ModelFit, data: BlockData, noise_terms: tuple[str, ...]) -> ModelFit:
    """A filter polished below its minimum is held at the minimum and the rest refitted."""
    floors = [_min_filter_s(t.identifier) for t in fit.terms]
    if all(floor is None or t.nl[0] >= floor for t, floor in zip(fit.terms, floors, strict=True)):
        return fit
    terms = tuple(
        t if floor is None else replace(t, nl=(floor,), fixed=True)
        for t, floor in zip(fit.terms, floors, strict=True)
    )
    return fit_model(terms, noise_terms, data, start=fit.noise)


def _nonlinear_std(fit: ModelFit, data: BlockData, index: int, j: int) -> float:
    """One standard deviation of a nonlinear parameter from the log-likelihood's curvature."""
    term = fit.terms[index]
    value = term.nl[j]
    h = max(0.02 * abs(value), 0.5 * data.block_s)

    def loglik(x: float) -> float:
        nl = list(term.nl)
        nl[j] = x
        terms = list(fit.terms)
        terms[index] = replace(term, nl=tuple(nl))
        return evaluate(terms, data, fit.gls).loglik

    lo = max(value - h, 1e-9)
    curvature = (2.0 * fit.loglik - loglik(lo) - loglik(value + h)) / (0.5 * (value + h - lo)) ** 2
    return 1.0 / math.sqrt(curvature) if curvature > 0 else math.inf


def fit_physics(rec: Recording, structure: Structure) -> FittedPhysics:
    """Fit ``structure`` (bias polynomial plus its effects) to ``rec`` jointly."""
    with single_blas_thread():
        return _fit(rec, structure)


def _fit(rec: Recording, structure: Structure) -> FittedPhysics:
    rec = rec.without_truth()
    data = build_blocks(rec)
    unit = channel_unit(rec)
    scale = channel_scale(rec, data)
    baseline = build_baseline(None, np.asarray(rec.time_s) - float(rec.time_s[0]), data.lattice_lsb_c)
    noise_terms = baseline.noise_terms
    current = fit_model(baseline.terms, noise_terms, data)
    for effect in (*structure.compensated, *structure.nuisance):
        current = _add(current, data, effect)
    notes: list[str] = []
    if structure.candidates and data.held_out is not None:
        # a cross-validation fold: the compensator's own test adds only what the rows it trains on
        # identify (the finder's naming may also read the held-out segment's temperature history)
        seen = analyse_profile(data, rec.meta, seen_only=True).identifiability
        unseen = [name for name in structure.candidates if not (name in seen and seen[name].identifiable)]
        notes += [
            f"{STAGE}: {name} not tried: the rows this fold trains on do not identify it" for name in unseen
        ]
        structure = replace(structure, candidates=tuple(n for n in structure.candidates if n not in unseen))
    if structure.candidates:
        current, structure, decided = extend(
            current,
            data,
            structure,
            add_trial,
            unit=unit,
            undetermined=lambda trial, name: _undetermined(trial, data, name, scale),
        )
        notes += decided
    terms = _rate_filter(current.terms)
    fit = _clamp_rate(fit_model(terms, noise_terms, data, start=current.noise), data, noise_terms)

    design = build_design(fit.terms, data)
    beta_ols = _least_squares(design, data)
    Xw = fit.gls.whiten(design.X)
    dof = max(data.n - design.X.shape[1], 1)
    cov = (fit.rss / dof) * np.linalg.pinv(Xw.T @ Xw)
    sd_linear = np.sqrt(np.maximum(np.diag(cov), 0.0))

    keep = {e.identifier for e in structure.compensated} | {BACKBONE}
    effects: list[EffectConfig] = []
    nuisance: list[EffectConfig] = []
    std: dict[str, dict[str, float]] = {}
    at_bound: list[str] = []
    flagged: list[str] = []
    why: dict[str, tuple[str, ...]] = {}
    for index, term in enumerate(fit.terms):
        definition = DEFINITIONS[term.identifier]
        if term.identifier not in EFFECTS:
            continue  # a noise trend column (rate_ramp) is part of the fit, not of the drift
        params = catalogue_params(definition, term, _owned(design, beta_ols, index))
        sd_lin = _owned(design, sd_linear, index)
        nonlinear = [name for name, _ in definition.finder.nonlinear]
        sd = {k: abs(v) for k, v in catalogue_params(definition, term, sd_lin).items() if k not in nonlinear}
        judged = term.identifier in keep
        reasons: list[str] = []
        for j, name in enumerate(nonlinear[: len(term.nl)]):
            if name in params and not term.fixed:
                sd[name] = _nonlinear_std(fit, data, index, j)
        for name, (_, lo, hi) in at_search_bound(term, data).items() if judged else ():
            if name not in params:
                continue
            shown = channel_param_name(name, unit)
            at_bound.append(f"{term.identifier}.{shown}")
            reasons.append(f"{shown} = {params[name]:.4g} sits at the end of its search range {lo:g}..{hi:g}")
        outside = implausible(term.identifier, params, scale) if judged else {}
        flagged += [f"{term.identifier}.{channel_param_name(name, unit)}" for name in outside]
        reasons += outside.values()
        if reasons:
            why[term.identifier] = tuple(reasons)
        config = EffectConfig(term.identifier, params)
        (effects if term.identifier in keep else nuisance).append(config)
        std[term.identifier] = sd
    order = list(EFFECTS)
    effects.sort(key=lambda e: order.index(e.identifier))
    return FittedPhysics(
        tuple(effects),
        tuple(nuisance),
        std,
        tuple(at_bound),
        tuple(flagged),
        data.n,
        data.block_s,
        structure,
        tuple(notes),
        unit,
        why,
    )
