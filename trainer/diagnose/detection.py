"""The smallest size of an effect this run would name: a weakly identifiable effect's detection limit.

An effect the finder does not name is either absent or too small for this run to see: its signature
is partly absorbed by the temperature polynomial, the terms found and the noise model (a warm-up on a
run that starts with a monotone ramp looks like the polynomial on that ramp). Silence cannot tell the
two apart; a detection limit can. For an effect with one amplitude column at fixed nonlinear
parameters, under the final model's noise covariance (whitened), adding the column with amplitude
``a`` lowers the residual sum of squares by ``a^2 q``, ``q`` the squared norm of the whitened column
orthogonal to the model's columns. With ``n`` weighted blocks, the scale profiled (``rss / n``), and
``k`` parameters the effect adds, the criterion (``BIC`` drop >= ``THRESHOLD``) names it when

    n ln(1 + a^2 q / rss) >= THRESHOLD + k ln(n),   i.e.   a >= sqrt(rss / q (exp((THRESHOLD + k ln n) / n) - 1)).

That closed form holds the noise at the final model's. The finder re-estimates it on both sides:
on a quiet run whose random walk sits at its lower bound, an effect the model leaves out raises the
estimated random walk, which then takes up much of it (a step is a random walk's increment), and the
closed form was 3 times too small for a step. So the stated limit is where the BIC drop with the
noise re-estimated on both sides reaches the threshold (:func:`_refitted`, searched from the closed
form up); the closed form stays as its start, and ``closed_form=True`` returns it (the tests of the
algebra).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from trainer.diagnose.blocks import block_means
from trainer.diagnose.model import PLAUSIBLE, ModelFit, Term, build_design, fit_model, search_bounds
from trainer.diagnose.select import THRESHOLD
from trainer.physics.catalogue import DEFINITIONS, flagged_range
from trainer.physics.catalogue.units import ChannelScale

GRID_POINTS = 5  # nonlinear values over the plausible range at which a limit is reported
REFIT_TOLERANCE = 1.05  # the re-estimated limit is found to within 5 %
REFIT_STEPS = 4  # false-position steps at most (each one noise fit)
REFIT_MAX_FACTOR = 64.0  # searched up to 64 times the closed form; beyond, a lower bound (at_least)


@dataclass(frozen=True)
class Limit:
    """At ``nl_value`` of the effect's nonlinear parameter: the smallest amplitude named, and the
    share of the effect's shape (beyond a constant) that the model's columns absorb."""

    nl_value: float
    amplitude: float
    absorbed: float
    at_least: bool = False  # not named even at this amplitude (REFIT_MAX_FACTOR x the closed form)


@dataclass(frozen=True)
class DetectionLimit:
    """A weakly identifiable effect not named: why it is weak and the smallest size named."""

    effect: str
    nl_name: str
    amp_name: str
    plausible_amp: tuple[float, float]
    limits: tuple[Limit, ...]
    reason: str
    recommended_test: str


def single_amplitude(effect: str) -> tuple[str, str] | None:
    """(nonlinear name, amplitude name) of an effect with one nonlinear parameter and one amplitude
    column; None for any other shape (a periodic's two columns, a polynomial)."""
    finder = DEFINITIONS[effect].finder
    amplitudes = [p.name for p in DEFINITIONS[effect].params if p.name not in dict(finder.nonlinear)]
    if len(finder.nonlinear) != 1 or len(amplitudes) != 1:
        return None
    return finder.nonlinear[0][0], amplitudes[0]


def limit_at(fit: ModelFit, effect: str, nl_value: float, *, closed_form: bool = False) -> Limit:
    """The detection limit of ``effect`` at ``nl_value`` added to ``fit`` (see the module docstring;
    ``closed_form``: at the model's noise, without re-estimating it)."""
    term = Term(effect, (float(nl_value),))
    design = build_design([*fit.terms, term], fit.data)
    own = np.array([owner == len(fit.terms) for owner, _ in design.roles])
    column = design.X[:, own][:, 0]
    limit = _limit(fit, design.X[:, ~own], column, 1 + term.n_free_nl, float(nl_value))
    return limit if closed_form else _refitted(fit, term, column, limit)


def _shape_columns(
    fit: ModelFit, effect: str, shape: np.ndarray, nl: tuple[float, ...]
) -> tuple[np.ndarray, np.ndarray, int]:
    """(the model's columns, the block means of ``shape``, parameters the instance adds as the
    search charges them: its columns and free nonlinear parameters)."""
    data = fit.data
    column = block_means(shape, data.samples_per_block, data.n)
    term = Term(effect, nl)
    design = build_design([*fit.terms, term], data)
    own = np.array([owner == len(fit.terms) for owner, _ in design.roles])
    return design.X[:, ~own], column, int(own.sum()) + term.n_free_nl


def shape_limit(
    fit: ModelFit, effect: str, shape: np.ndarray, nl: tuple[float, ...], *, closed_form: bool = False
) -> Limit:
    """The detection limit of one instance's own shape: ``shape`` its contribution per unit of
    amplitude at full rate (a periodic at its phase, a step at its time; ``nl`` its nonlinear
    parameters), charged as the search charges the effect (its columns and nonlinear parameters).
    Below it this run cannot be asked to name the instance."""
    model_columns, column, added = _shape_columns(fit, effect, shape, nl)
    limit = _limit(fit, model_columns, column, added, float("nan"))
    return limit if closed_form else _refitted(fit, Term(effect, nl), column, limit)


def shape_content(
    fit: ModelFit, effect: str, shape: np.ndarray, nl: tuple[float, ...]
) -> tuple[float, float]:
    """(amplitude, standard error) of one instance's shape in what ``fit`` leaves unexplained: its
    GLS coefficient beside the model's columns, at the model's noise. A run's own content of a shape
    below its limit: an instance of that shape added to the run is found at the sum of the two."""
    model_columns, column, _ = _shape_columns(fit, effect, shape, nl)
    others = fit.gls.whiten(model_columns)
    white = fit.gls.whiten(column)
    coefficients, *_ = np.linalg.lstsq(others, white, rcond=None)
    orthogonal = white - others @ coefficients
    q = float(orthogonal @ orthogonal)
    if q <= 0.0:
        return 0.0, math.inf
    amplitude = float(orthogonal @ fit.gls.whiten(fit.residual)) / q
    return amplitude, math.sqrt(fit.rss / fit.gls.n_weighted / q)


def evidence_beside(fit: ModelFit, index: int, beside: Sequence[Term]) -> float:
    """BIC drop that term ``index`` of ``fit`` earns once ``beside`` are in the model too (both sides
    refitted as the finder fits, at the model's noise terms). Below :data:`THRESHOLD` the finding
    shares its signature with them: a run carrying both cannot be asked to name it (a step just after
    a reversal beside a filtered rate term that switches there)."""
    extra = tuple(beside)
    others = tuple(t for k, t in enumerate(fit.terms) if k != index)
    with_it = fit_model(fit.terms + extra, fit.noise.terms, fit.data, start=fit.noise)
    without = fit_model(others + extra, fit.noise.terms, fit.data, start=fit.noise)
    return without.bic - with_it.bic


def _limit(
    fit: ModelFit, model_columns: np.ndarray, column: np.ndarray, added: int, nl_value: float
) -> Limit:
    others = fit.gls.whiten(model_columns)
    white = fit.gls.whiten(column)
    coefficients, *_ = np.linalg.lstsq(others, white, rcond=None)
    orthogonal = white - others @ coefficients
    constant = fit.gls.whiten(np.ones(fit.data.n))
    beyond_constant = white - constant * float(constant @ white) / float(constant @ constant)
    q = float(orthogonal @ orthogonal)
    n = fit.gls.n_weighted
    needed = math.expm1((THRESHOLD + added * math.log(n)) / n)
    amplitude = math.sqrt(fit.rss / q * needed) if q > 0 else math.inf
    shape = float(beyond_constant @ beyond_constant)
    return Limit(nl_value, amplitude, 1.0 - q / shape if shape > 0 else 1.0)


def _refitted(fit: ModelFit, term: Term, column: np.ndarray, closed: Limit) -> Limit:
    """``closed`` with its amplitude raised to where the criterion names ``column`` (block means per
    unit amplitude of ``term``'s instance) with the noise re-estimated on both sides, as the search
    does: the model without it refitted to the data plus ``a column``, against the model with it
    (whose fit does not depend on ``a``: the column absorbs it), charged its free nonlinear
    parameters. The BIC drop grows about as ``a**2``: the root is bracketed from the closed form up
    and found by false position in ``a**2`` (2 to 8 noise fits on the runs measured)."""
    if not math.isfinite(closed.amplitude) or closed.amplitude <= 0.0:
        return closed
    data, noise_terms = fit.data, fit.noise.terms
    held = replace(term, fixed=True)
    with_it = fit_model([*fit.terms, held], noise_terms, data, start=fit.noise, optimise=False, rounds=1)
    charged = with_it.bic + term.n_free_nl * math.log(data.n)

    def drop(amplitude: float) -> float:
        """The BIC drop the instance at ``amplitude`` earns, less the threshold."""
        shifted = replace(data, accel=data.accel + amplitude * column)
        without = fit_model(fit.terms, noise_terms, shifted, start=fit.noise, optimise=False, rounds=1)
        return without.bic - charged - THRESHOLD

    low, low_drop = closed.amplitude, drop(closed.amplitude)
    if low_drop >= 0.0:
        return closed
    high, high_drop = 2.0 * low, drop(2.0 * low)
    while high_drop < 0.0:
        if high >= REFIT_MAX_FACTOR * closed.amplitude:
            return replace(closed, amplitude=high, at_least=True)
        low, low_drop, high = high, high_drop, 2.0 * high
        high_drop = drop(high)
    for _ in range(REFIT_STEPS):
        if high / low <= REFIT_TOLERANCE:
            break
        fraction = -low_drop / (high_drop - low_drop)
        middle = math.sqrt(low**2 + fraction * (high**2 - low**2))
        middle = min(max(middle, low * math.sqrt(REFIT_TOLERANCE)), high / math.sqrt(REFIT_TOLERANCE))
        middle_drop = drop(middle)
        if middle_drop >= 0.0:
            high, high_drop = middle, middle_drop
        else:
            low, low_drop = middle, middle_drop
    return replace(closed, amplitude=high)


def detection_limit(
    fit: ModelFit, effect: str, reason: str, recommended_test: str, scale: ChannelScale | None = None
) -> DetectionLimit | None:
    """Limits of ``effect`` over its nonlinear parameter's plausible range (log-spaced); the plausible
    amplitude is the channel's (``scale``: a gyroscope's in deg/s, bounded by its drift span)."""
    names = single_amplitude(effect)
    if names is None:
        return None
    nl_name, amp_name = names
    # the plausible range where the search looks (a rate term's plausible 0 s is one block here)
    (search_lo, search_hi), *_ = search_bounds(effect, fit.data)
    plausible_lo, plausible_hi = PLAUSIBLE[(effect, nl_name)]
    lo, hi = max(plausible_lo, search_lo), min(plausible_hi, search_hi)
    if not 0.0 < lo <= hi:
        return None
    grid = np.geomspace(lo, hi, GRID_POINTS)
    return DetectionLimit(
        effect,
        nl_name,
        amp_name,
        flagged_range(effect, amp_name, scale) or PLAUSIBLE[(effect, amp_name)],
        tuple(limit_at(fit, effect, float(v)) for v in grid),
        reason,
        recommended_test,
    )
