"""One search per candidate effect, on top of a current model.

Each search profiles the candidate's nonlinear parameter over its plausible range (a grid, then a
bounded local refinement, all other nonlinear parameters polished jointly) at the current noise
covariance, with every amplitude and the ``bias_poly`` coefficients solved by GLS inside. Steps
and periodic components are scanned exhaustively with a vectorised projection (one whitening of
all candidate columns at once). The noise covariance is re-estimated afterwards by the selector
for the candidates that look promising.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from trainer.diagnose.blocks import BlockData
from trainer.diagnose.locate import fit_sine, spectral_peaks
from trainer.diagnose.model import (
    ModelFit,
    Term,
    build_design,
    evaluate,
    periodic_columns,
    polish,
    search_bounds,
)
from trainer.physics.catalogue import (
    COVARIANCE_NOISE,
    DEFINITIONS,
    MULTI_INSTANCE,
    excluded,
    nonlinear_defaults,
)
from trainer.physics.catalogue.base import catalogue_params

GRID_POINTS = {k: d.finder.grid_points for k, d in DEFINITIONS.items() if d.finder.grid_points}
FAST_PERIOD_BLOCKS = 4.0  # periods shorter than this many blocks are scored on the fine grid


@dataclass
class Proposal:
    """A candidate model: current terms plus one effect (or one noise term)."""

    effect: str
    terms: tuple[Term, ...]
    noise_terms: tuple[str, ...]
    fit_fixed_noise: ModelFit | None  # at the current noise ratios (a lower bound on the gain)
    spectral_evidence: float | None = None  # 2 delta logL of a fast periodic on the fine grid
    spectral_n: int = 0
    note: str = ""


def coincides(term: Term, others: Sequence[Term], data: BlockData) -> bool:
    """Whether ``term`` is, within the data's resolution, an instance already in ``others``."""
    same = DEFINITIONS[term.identifier].finder.same_instance
    return same is not None and any(
        o.identifier == term.identifier and o is not term and same(term, o, data) for o in others
    )


def has_duplicates(terms: Sequence[Term], data: BlockData) -> bool:
    """Whether two instances of one effect in ``terms`` coincide (they would be one instance)."""
    return any(coincides(term, terms[:k], data) for k, term in enumerate(terms))


def _taken(effect: str, values: np.ndarray, current: ModelFit, data: BlockData) -> np.ndarray:
    """Mask of scanned nonlinear values that coincide with an instance of ``effect`` in the model."""
    if not any(t.identifier == effect for t in current.terms):
        return np.zeros(values.size, dtype=bool)
    return np.array([coincides(Term(effect, (float(v),)), current.terms, data) for v in values])


def _log_grid(lo: float, hi: float, n: int) -> np.ndarray:
    return np.logspace(math.log10(lo), math.log10(hi), n)


def _profile_1d(
    current: ModelFit, data: BlockData, new: Term, bounds: tuple[float, float] | None = None
) -> ModelFit:
    """Log grid over the new term's single nonlinear parameter within ``bounds`` (default: its
    search bounds), then a joint polish."""
    ((lo, hi),) = (bounds,) if bounds is not None else search_bounds(new.identifier, data)
    grid = _log_grid(lo, hi, GRID_POINTS[new.identifier])
    best: ModelFit | None = None
    for value in grid:
        fit = evaluate((*current.terms, replace(new, nl=(float(value),))), data, current.gls)
        if best is None or fit.loglik > best.loglik:
            best = fit
    assert best is not None
    return polish(best.terms, data, current.gls)


def _whitened_base(current: ModelFit, data: BlockData) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal basis of the whitened current design and the whitened residual."""
    design = build_design(current.terms, data)
    Xw = current.gls.whiten(design.X)
    yw = current.gls.whiten(data.accel - design.offset)
    q, _ = np.linalg.qr(Xw)
    return q, yw - q @ (q.T @ yw)


def _step_columns(current: ModelFit, data: BlockData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step times (block boundaries), the whitened step columns orthogonal to the current design,
    and the whitened residual."""
    n = data.n
    q, r = _whitened_base(current, data)
    j = np.arange(2, n - 1)
    steps = (np.arange(n)[:, None] >= j[None, :]).astype(np.float64)
    zw = current.gls.whiten(steps)
    return data.starts[j], zw - q @ (q.T @ zw), r


def scan_steps(current: ModelFit, data: BlockData) -> tuple[np.ndarray, np.ndarray]:
    """Step times (block boundaries) and the RSS after adding a step at each (GLS, vectorised)."""
    times, zp, r = _step_columns(current, data)
    norms = np.einsum("ij,ij->j", zp, zp)
    gain = (r @ zp) ** 2 / np.maximum(norms, 1e-300)
    return times, float(r @ r) - gain


def scan_step_pairs(current: ModelFit, data: BlockData) -> tuple[np.ndarray, np.ndarray]:
    """Step times and the RSS after adding two steps at every pair of them, both fitted jointly
    (GLS, vectorised: the 2x2 normal equations of each pair from one Gram matrix). Two steps that
    nearly cancel (a level that leaves and comes back) explain little one at a time: a forward
    search adding one step per round would stop before either."""
    times, zp, r = _step_columns(current, data)
    gram = zp.T @ zp
    b = r @ zp
    diag = np.diag(gram)
    det = diag[:, None] * diag[None, :] - gram**2
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = (
            diag[None, :] * b[:, None] ** 2
            - 2 * gram * b[:, None] * b[None, :]
            + diag[:, None] * b[None, :] ** 2
        ) / det
    gain = np.where(det > 1e-12 * np.outer(diag, diag), gain, 0.0)
    return times, float(r @ r) - gain


def scan_periods(current: ModelFit, data: BlockData, periods: np.ndarray) -> np.ndarray:
    """RSS after adding a block-averaged sinusoid of each period (GLS, vectorised)."""
    q, r = _whitened_base(current, data)
    out = np.empty(periods.size)
    chunk = 256
    for k0 in range(0, periods.size, chunk):
        ps = periods[k0 : k0 + chunk]
        cols = np.empty((data.n, 2 * ps.size))
        for i, p in enumerate(ps):
            cols[:, 2 * i], cols[:, 2 * i + 1] = periodic_columns(data.t, float(p), data.block_s)
        zw = current.gls.whiten(cols)
        zp = zw - q @ (q.T @ zw)
        s, c = zp[:, 0::2], zp[:, 1::2]
        gss = np.einsum("ij,ij->j", s, s)
        gcc = np.einsum("ij,ij->j", c, c)
        gsc = np.einsum("ij,ij->j", s, c)
        bs, bc = r @ s, r @ c
        det = np.maximum(gss * gcc - gsc**2, 1e-300)
        gain = (gcc * bs**2 - 2 * gsc * bs * bc + gss * bc**2) / det
        out[k0 : k0 + ps.size] = float(r @ r) - gain
    return out


def propose_step(current: ModelFit, data: BlockData, effect: str) -> Proposal:
    """A step-like ``effect`` (``bias_step``) at the best block boundary, then polished."""
    times, rss = scan_steps(current, data)
    rss = np.where(_taken(effect, times, current, data), np.inf, rss)
    k = int(np.argmin(rss))
    start = Term(effect, (float(times[k]),))
    fit = polish((*current.terms, start), data, current.gls)
    return Proposal(effect, fit.terms, current.noise.terms, fit)


def propose_step_pair(current: ModelFit, data: BlockData, effect: str) -> Proposal | None:
    """Two instances of a step-like ``effect`` at the best pair of block boundaries (not within two
    blocks of each other or of a step in the model), then polished; ``None`` when no pair is left."""
    times, rss = scan_step_pairs(current, data)
    taken = _taken(effect, times, current, data)
    k = np.arange(times.size)
    allowed = (k[None, :] - k[:, None] > 2) & ~taken[:, None] & ~taken[None, :]
    rss = np.where(allowed, rss, np.inf)
    if not np.isfinite(rss).any():
        return None
    first, second = np.unravel_index(int(np.argmin(rss)), rss.shape)
    start = (Term(effect, (float(times[first]),)), Term(effect, (float(times[second]),)))
    fit = polish((*current.terms, *start), data, current.gls)
    return Proposal(effect, fit.terms, current.noise.terms, fit, note="a pair of steps, placed jointly")


def propose_slow_periodic(current: ModelFit, data: BlockData, effect: str) -> Proposal | None:
    lo = FAST_PERIOD_BLOCKS * data.block_s
    hi = 0.5 * data.duration_s
    if hi <= lo:
        return None
    f = np.arange(1.0 / hi, 1.0 / lo, 1.0 / (4.0 * data.duration_s))
    periods = 1.0 / f
    rss = scan_periods(current, data, periods)
    rss = np.where(_taken(effect, periods, current, data), np.inf, rss)
    k = int(np.argmin(rss))
    start = Term(effect, (float(periods[k]),))
    fit = polish((*current.terms, start), data, current.gls)
    return Proposal(effect, fit.terms, current.noise.terms, fit)


def fine_residual(current: ModelFit, data: BlockData) -> np.ndarray:
    """Fine-grid data minus the current model interpolated from the block centres.

    A term with a fine-grid form (a periodic component fitted on the blocks) is subtracted exactly
    on the fine grid instead: interpolating a period of a few blocks linearly leaves its harmonics
    in the residual, where the fast search would name them (a 30 s "component" beside 150 s).
    """
    block_model = current.prediction.copy()
    exact = np.zeros(data.fine_t.size)
    for index, term in enumerate(current.terms):
        definition = DEFINITIONS[term.identifier]
        fine_offset = definition.finder.fine_offset
        if fine_offset is None or term.offset is not None:
            continue
        params = catalogue_params(definition, term, current.linear(index))
        nonlinear = {name for name, _ in definition.finder.nonlinear}
        held = replace(
            term, offset=tuple(params[p.name] for p in definition.params if p.name not in nonlinear)
        )
        block_model -= current.term_contribution(index)
        exact += fine_offset(held, data.fine_t)
    return data.fine_accel - np.interp(data.fine_t, data.t, block_model) - exact


def propose_fast_periodic(current: ModelFit, data: BlockData, effect: str) -> Proposal | None:
    """A periodic component too fast for the blocks, scored by the spectral test on the fine grid."""
    lo = max(4.0, 2.5 * data.fine_step_s)
    hi = FAST_PERIOD_BLOCKS * data.block_s
    if hi <= lo * 1.05:
        return None
    x = fine_residual(current, data)
    for term in current.terms:  # components already found are removed before looking again
        fine_offset = DEFINITIONS[term.identifier].finder.fine_offset
        if fine_offset is not None and term.offset is not None:
            x = x - fine_offset(term, data.fine_t)
    peaks = spectral_peaks(x, data.fine_step_s, lo, hi, max_peaks=3, alpha=0.5)
    peaks = [p for p in peaks if not coincides(Term(effect, (p.period_s,)), current.terms, data)]
    if not peaks:
        return None
    peak = peaks[0]
    sine = fit_sine(data.fine_t, x, peak.period_s, data.duration_s)
    evidence = sine.delta_rss / peak.noise_var
    term = Term(effect, (sine.period_s,), fixed=True, offset=(sine.amp_mg, sine.phase_rad))
    fit = evaluate((*current.terms, term), data, current.gls)
    return Proposal(
        effect,
        fit.terms,
        current.noise.terms,
        fit,
        spectral_evidence=evidence,
        spectral_n=int(x.size),
        note=f"spectral test on the {data.fine_step_s:g} s grid, peak/background {peak.ratio:.1f}",
    )


def _propose_profile(current: ModelFit, data: BlockData, effect: str) -> list[Proposal]:
    fit = _profile_1d(current, data, Term(effect, (1.0,)))
    return [Proposal(effect, fit.terms, current.noise.terms, fit)]


def _propose_linear(current: ModelFit, data: BlockData, effect: str) -> list[Proposal]:
    """Linear columns with optional nonlinear parameters held at their catalogue defaults, or, when
    the definition declares ``freed_bounds`` and the BIC (which charges the freed parameter) prefers
    it, freed within them: a rate term seen through a thermal filter (``temp_rate`` with ``tau_s``
    60 s) fitted instantaneously leaves its corners to a hysteresis and steps and comes out at a
    quarter to a half of its size."""
    defaults = nonlinear_defaults(effect)
    fit = polish((*current.terms, Term(effect, defaults, fixed=bool(defaults))), data, current.gls)
    freed_bounds = DEFINITIONS[effect].finder.freed_bounds
    if freed_bounds is not None:
        ((lo, hi),) = freed_bounds(data, current.identifiers)
        freed = _profile_1d(current, data, Term(effect, defaults), (lo, hi))
        if freed.bic < fit.bic and lo <= freed.terms[len(current.terms)].nl[0] <= hi:
            fit = freed
    return [Proposal(effect, fit.terms, current.noise.terms, fit)]


def propose_freed_wide(current: ModelFit, data: BlockData, effect: str) -> list[Proposal]:
    """A term with ``freed_bounds`` freed over its whole search range instead (``temp_rate``: up to
    600 s, not :data:`~trainer.physics.catalogue.temp_rate.FREED_MAX_S`). Not for naming: through
    a long filter a rate term takes a real run's own loop. The physics compensator's
    cross-validated stage tries it, where a term must predict blocks it was not fitted on: a
    gyroscope's rate term through 330 s (the realistic experiment) is otherwise never placed."""
    definition = DEFINITIONS[effect]
    if definition.finder.search != "linear" or definition.finder.freed_bounds is None:
        return []
    if any(excluded(effect, present) for present in current.identifiers):
        return []
    ((lo, _),) = definition.finder.freed_bounds(data, current.identifiers)
    ((_, hi),) = search_bounds(effect, data)
    if not hi > lo:
        return []
    fit = _profile_1d(current, data, Term(effect, nonlinear_defaults(effect)), (lo, hi))
    return [Proposal(effect, fit.terms, current.noise.terms, fit)]


def _propose_lattice(current: ModelFit, data: BlockData, effect: str) -> list[Proposal]:
    """The thermometer's lattice LSB is read off the data, not searched."""
    if data.lattice_lsb_c is None:
        return []
    term = Term(effect, (data.lattice_lsb_c,), fixed=True)
    fit = polish((*current.terms, term), data, current.gls)
    return [Proposal(effect, fit.terms, current.noise.terms, fit)]


def _propose_step(current: ModelFit, data: BlockData, effect: str) -> list[Proposal]:
    return [propose_step(current, data, effect)]


def _propose_sinusoid(current: ModelFit, data: BlockData, effect: str) -> list[Proposal]:
    slow = propose_slow_periodic(current, data, effect)
    fast = propose_fast_periodic(current, data, effect)
    return [p for p in (slow, fast) if p]


def _propose_noise(current: ModelFit, data: BlockData, effect: str) -> list[Proposal]:
    if effect in current.noise.terms:
        return []
    noise = tuple(t for t in COVARIANCE_NOISE if t in current.noise.terms or t == effect)
    return [Proposal(effect, current.terms, noise, None)]


# The search strategies a definition's ``finder.search`` names.
SEARCHES = {
    "profile": _propose_profile,
    "linear": _propose_linear,
    "lattice": _propose_lattice,
    "step": _propose_step,
    "sinusoid": _propose_sinusoid,
    "noise": _propose_noise,
}


def _room(current: ModelFit, effect: str, instances: int) -> bool:
    """Whether ``instances`` more of ``effect`` may enter the model: within its ``max_terms``, and
    nothing in the model describes the same physics."""
    present = sum(1 for i in current.identifiers if i == effect)
    return present + instances <= DEFINITIONS[effect].finder.max_terms and not any(
        excluded(effect, other) for other in current.identifiers
    )


def confusable(first: str, second: str) -> bool:
    """Whether either effect declares the other a confounder."""
    return any(
        b in DEFINITIONS[a].finder.confounders
        for a, b in ((first, second), (second, first))
        if a in DEFINITIONS
    )


def propose_pair(current: ModelFit, data: BlockData, effect: str) -> Proposal | None:
    """Two instances of ``effect`` placed jointly, for an effect whose instances the catalogue allows
    several of and that is searched as a step (``None`` otherwise, without room for two, or beside a
    term declared confusable with it)."""
    if (
        DEFINITIONS[effect].finder.search != "step"
        or effect not in MULTI_INSTANCE
        or not _room(current, effect, 2)
    ):
        return None
    if any(confusable(effect, present) for present in current.identifiers):
        # a term in the model whose signature a step shares (a rate term's jump at a corner, a branch
        # offset's switch at a reversal): a pair of steps there would redescribe it, not add to it
        return None
    proposal = propose_step_pair(current, data, effect)
    return None if proposal is None or has_duplicates(proposal.terms, data) else proposal


def propose(current: ModelFit, data: BlockData, effect: str) -> list[Proposal]:
    """Proposals for adding ``effect`` (empty when it does not apply to the current model)."""
    definition = DEFINITIONS.get(effect)
    search = None if definition is None else definition.finder.search
    if definition is None or search is None:
        raise ValueError(f"no search for {effect!r}")
    if not _room(current, effect, 1):
        return []
    # a polished instance that lands on one already in the model is that instance, not a new one
    return [p for p in SEARCHES[search](current, data, effect) if not has_duplicates(p.terms, data)]
