"""A physics model on block means: catalogue terms -> design matrix -> GLS fit -> catalogue params.

Each effect is split into nonlinear parameters (time constants, hysteresis width, period, step
time), searched numerically, and linear ones (amplitudes and the ``bias_poly`` coefficients),
solved by generalised least squares inside every evaluation (variable projection). The
``bias_poly`` is therefore always re-fitted jointly with the other terms: the point of the finder
is that a polynomial absorbs part of a missing effect, and only what it cannot absorb is evidence.

The columns use the physics package's own building blocks (``thermal.lowpass``,
``thermal.play_operator``) with the catalogue's formulas, and :func:`catalogue_effects` turns a
fit back into ``EffectConfig`` instances that ``physics.effects.drift`` evaluates identically.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import minimize

from trainer.diagnose.blocks import BlockData
from trainer.diagnose.gls import Gls, NoiseState, fit_noise, initial_state
from trainer.physics import catalogue
from trainer.physics.catalogue import DEFINITIONS, EFFECTS, NOISE, WHITE_NOISE
from trainer.physics.catalogue.base import BlockDesign, catalogue_params
from trainer.physics.catalogue.periodic import periodic_columns as periodic_columns
from trainer.physics.effects import EffectConfig

# Catalogue plausible ranges (physics-catalogue.md, kept next to each parameter in its definition);
# the search goes somewhat beyond them so a value at the edge is seen as such, and the report flags
# values outside.
PLAUSIBLE: dict[tuple[str, str], tuple[float, float]] = catalogue.PLAUSIBLE
POLISH_EVALS = 120
POLISH_EVALS_PER_PARAM = 60


def search_bounds(identifier: str, data: BlockData) -> tuple[tuple[float, float], ...]:
    """Bounds of each nonlinear parameter of ``identifier`` for this recording."""
    return DEFINITIONS[identifier].finder.bounds(data)


@dataclass(frozen=True)
class Term:
    """One effect instance in a model.

    ``nl``: its nonlinear parameter values (``NONLINEAR`` order). ``fixed``: they are held, not
    searched. ``offset``: linear parameters that are also held (a fast periodic component fitted
    on the fine grid enters the block model as a known contribution, with no free columns).
    """

    identifier: str
    nl: tuple[float, ...] = ()
    fixed: bool = False
    offset: tuple[float, ...] | None = None

    @property
    def n_free_nl(self) -> int:
        """Parameters this term adds to the BIC count besides its linear columns: its definition's
        rule (a scanned step time or period counts twice), else its free nonlinear parameters."""
        rule = DEFINITIONS[self.identifier].finder.bic_nonlinear
        if rule is not None:
            return rule
        return 0 if self.fixed else len(self.nl)


@dataclass
class Design:
    X: np.ndarray
    roles: list[tuple[int, str]]
    offset: np.ndarray
    T_pm: np.ndarray


def build_design(terms: Sequence[Term], data: BlockData) -> Design:
    """Design matrix of ``terms`` on the block means (the backbone's columns first).

    Order of evaluation: the proof-mass temperature (``thermal_lag``), then every other term's
    columns in term order (``hysteresis`` also sets what the polynomial reads), then the
    backbone's (``bias_poly``), which read the finished temperature chain.
    """
    definitions = [DEFINITIONS[term.identifier].finder for term in terms]
    dequant = any(d.dequantize for d in definitions)
    T = data.temperature(dequant)
    state = BlockDesign(data, T, data.rate(dequant), T, T, np.zeros(data.n))
    for term, d in zip(terms, definitions, strict=True):
        if d.proof_mass is not None:
            state.T_pm = d.proof_mass(term, T, data.block_s)
    state.T_b = state.T_pm
    first: list[tuple[int, str, np.ndarray]] = []
    extra: list[tuple[int, str, np.ndarray]] = []
    for index, (term, d) in enumerate(zip(terms, definitions, strict=True)):
        if d.columns is not None and not d.backbone:
            extra += [(index, role, column) for role, column in d.columns(term, state)]
    for index, (term, d) in enumerate(zip(terms, definitions, strict=True)):
        if d.backbone and d.columns is not None:
            first += [(index, role, column) for role, column in d.columns(term, state)]
    columns = [column for _, _, column in (*first, *extra)]
    roles = [(index, role) for index, role, _ in (*first, *extra)]
    return Design(np.column_stack(columns), roles, state.offset, state.T_pm)


@dataclass
class ModelFit:
    """A fitted model: terms with their nonlinear values, noise state, GLS coefficients."""

    terms: tuple[Term, ...]
    gls: Gls
    beta: np.ndarray
    roles: list[tuple[int, str]]
    rss: float
    loglik: float
    n_params: int
    prediction: np.ndarray
    data: BlockData = field(repr=False)

    @property
    def noise(self) -> NoiseState:
        return self.gls.state

    @property
    def bic(self) -> float:
        return -2.0 * self.loglik + self.n_params * math.log(self.data.n)

    @property
    def residual(self) -> np.ndarray:
        return self.data.accel - self.prediction

    @property
    def identifiers(self) -> list[str]:
        return [term.identifier for term in self.terms]

    def noise_params(self) -> dict[str, dict[str, float]]:
        """Catalogue noise coefficients. White noise comes from the full-rate first differences:
        on block means it is barely separable from flicker, at the sample rate it dominates."""
        values = self.gls.noise_params(self.rss)
        values[WHITE_NOISE] = self.data.white_n_mg_rt_s
        return {term: {NOISE[term].params[0].name: value} for term, value in values.items()}

    def linear(self, index: int) -> dict[str, float]:
        return {
            role: float(b) for (owner, role), b in zip(self.roles, self.beta, strict=True) if owner == index
        }

    def term_contribution(self, index: int) -> np.ndarray:
        """Block-level contribution of one non-poly term (its columns times its coefficients)."""
        design = build_design(self.terms, self.data)
        mask = np.array([owner == index for owner, _ in self.roles])
        out = design.X[:, mask] @ self.beta[mask]
        term = self.terms[index]
        if term.offset is not None:
            out = out + build_design([term], self.data).offset
        return out


def count_params(terms: Sequence[Term], n_columns: int, noise: NoiseState) -> int:
    return n_columns + sum(term.n_free_nl for term in terms) + 1 + len(noise.terms)


def evaluate(terms: Sequence[Term], data: BlockData, gls: Gls) -> ModelFit:
    design = build_design(terms, data)
    # the block means themselves when no term adds a known offset: whitened once per factor
    y = data.accel - design.offset if design.offset.any() else data.accel
    result = gls.fit(design.X, y)
    return ModelFit(
        terms=tuple(terms),
        gls=gls,
        beta=result.beta,
        roles=design.roles,
        rss=result.rss,
        loglik=result.loglik,
        n_params=count_params(terms, design.X.shape[1], gls.state),
        prediction=design.X @ result.beta + design.offset,
        data=data,
    )


def _free_slots(terms: Sequence[Term], data: BlockData) -> list[tuple[int, int, float, float, bool]]:
    """(term index, nl index, lower, upper, log-scaled) of every searchable nonlinear parameter."""
    slots = []
    for i, term in enumerate(terms):
        if term.fixed or term.offset is not None:
            continue
        names = DEFINITIONS[term.identifier].finder.nonlinear
        bounds = search_bounds(term.identifier, data)
        for j, ((_, logged), (lo, hi)) in enumerate(zip(names, bounds, strict=True)):
            if j < len(term.nl):  # an optional nonlinear parameter left out is held at its default
                slots.append((i, j, lo, hi, logged))
    return slots


def with_values(terms: Sequence[Term], slots: list, z: np.ndarray) -> list[Term]:
    out = list(terms)
    for (i, j, lo, hi, logged), zi in zip(slots, z, strict=True):
        value = float(np.clip(10.0**zi if logged else zi, lo, hi))
        nl = list(out[i].nl)
        nl[j] = value
        out[i] = replace(out[i], nl=tuple(nl))
    return out


def polish(terms: Sequence[Term], data: BlockData, gls: Gls, *, max_evals: int | None = None) -> ModelFit:
    """Joint local optimisation of all free nonlinear parameters at fixed noise ratios.

    The evaluation budget grows with the number of free parameters (``POLISH_EVALS_PER_PARAM``
    each, at least ``POLISH_EVALS``): with two or three accepted effects a fixed budget stopped
    the simplex before the parameters of the earlier ones had moved.
    """
    slots = _free_slots(terms, data)
    if not slots:
        return evaluate(terms, data, gls)
    if max_evals is None:
        max_evals = max(POLISH_EVALS, POLISH_EVALS_PER_PARAM * len(slots))
    z0 = np.array([math.log10(terms[i].nl[j]) if lg else terms[i].nl[j] for i, j, _, _, lg in slots])
    steps = np.array([0.08 if lg else max(data.block_s, 0.01 * (hi - lo)) for _, _, lo, hi, lg in slots])

    def objective(z: np.ndarray) -> float:
        return -evaluate(with_values(terms, slots, z), data, gls).loglik

    simplex = [z0] + [z0 + np.eye(z0.size)[k] * steps[k] for k in range(z0.size)]
    result = minimize(
        objective,
        z0,
        method="Nelder-Mead",
        options={"initial_simplex": np.array(simplex), "maxfev": max_evals, "xatol": 1e-3, "fatol": 0.01},
    )
    best = result.x if result.fun <= objective(z0) else z0
    return evaluate(with_values(terms, slots, best), data, gls)


def fit_model(
    terms: Sequence[Term],
    noise_terms: Sequence[str],
    data: BlockData,
    *,
    start: NoiseState | None = None,
    gls: Gls | None = None,
    refit_noise: bool = True,
    rounds: int = 2,
    optimise: bool = True,
) -> ModelFit:
    """Fit ``terms`` with ``noise_terms``: nonlinear polish and noise ML, alternated ``rounds`` times.

    A cold start (no ``start`` ratios for these noise terms) explores the noise ratios widely first.
    """
    explore = start is None or any(term not in start.terms for term in noise_terms)
    if gls is None:
        if start is None or start.terms != tuple(noise_terms):
            start = _restrict(start, noise_terms, data)
        gls = Gls(data.n, data.block_s, data.duration_s, start, data.held_out)
    fit = polish(terms, data, gls) if optimise else evaluate(terms, data, gls)
    if not refit_noise:
        return fit
    for _ in range(rounds):
        design = build_design(fit.terms, data)
        new_gls, _ = fit_noise(
            design.X,
            data.accel - design.offset,
            data.n,
            data.block_s,
            data.duration_s,
            fit.noise,
            explore=explore,
            held_out=data.held_out,
        )
        explore = False
        moved = np.max(np.abs(np.subtract(new_gls.state.log_ratios, fit.noise.log_ratios)), initial=0.0)
        fit = (
            polish(fit.terms, data, new_gls)
            if optimise and _free_slots(fit.terms, data)
            else evaluate(fit.terms, data, new_gls)
        )
        if moved < 0.15:
            break
    return fit


def _restrict(start: NoiseState | None, noise_terms: Sequence[str], data: BlockData) -> NoiseState:
    """A start state for ``noise_terms``, reusing ratios of ``start`` where it has them."""
    base = initial_state(noise_terms, data.block_s, data.white_n_mg_rt_s)
    if start is None:
        return base
    known = dict(zip(start.terms, start.log_ratios, strict=True))
    logs = tuple(known.get(term, lr) for term, lr in zip(base.terms, base.log_ratios, strict=True))
    return NoiseState(base.terms, logs)


def catalogue_effects(fit: ModelFit) -> list[EffectConfig]:
    """The fitted terms as catalogue ``EffectConfig`` instances (identifiers, names, units).

    Model terms that are not catalogue effects (the ``rate_ramp`` noise trend) are left out.
    """
    effects: list[EffectConfig] = []
    for index, term in enumerate(fit.terms):
        definition = EFFECTS.get(term.identifier)
        if definition is None:
            continue
        effects.append(EffectConfig(term.identifier, catalogue_params(definition, term, fit.linear(index))))
    return effects
