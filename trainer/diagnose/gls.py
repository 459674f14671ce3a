"""Generalised least squares on block means under the IEEE 952 noise model.

Bias instability (flicker) and rate random walk make neighbouring block means correlated; an
ordinary least-squares BIC would then see structure in pure noise and name effects that are not
there. The covariance of the block means is modelled as

    C = s^2 (I + rho_b F + rho_k R)

with ``s^2 = n^2 / B`` the white-noise variance of a block mean, ``F`` the flicker covariance for
``b = 1`` (the simulator's Gauss-Markov bank sampled at the block period, so its Allan deviation is
flat at 0.664 b) and ``R`` the covariance of block means of a random walk started at the first
sample (``k = 1``). ``s^2`` is profiled out analytically; the ratios are fitted by maximum
likelihood. The likelihood of a linear model under ``C`` is computed with one Cholesky factor.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.linalg import solve_triangular
from scipy.linalg.lapack import dpotrf
from scipy.optimize import minimize

from trainer.physics.catalogue import COVARIANCE_NOISE, NOISE, WHITE_NOISE

NOISE_CANDIDATES: tuple[str, ...] = COVARIANCE_NOISE
LOG_RATIO_BOUNDS = (-9.0, 7.0)
HELD_OUT_VARIANCE = 1e12  # a held-out block's extra variance (units of the white block variance)


def covariance_term(term: str) -> tuple[Callable[[int, float, float], np.ndarray], float]:
    """A covariance noise term's unit covariance and starting coefficient (its role sets both)."""
    finder = NOISE[term].finder
    assert finder.covariance is not None and finder.start_coefficient is not None, term
    return finder.covariance, finder.start_coefficient


@lru_cache(maxsize=8)
def unit_matrices(n: int, block_s: float, duration_s: float) -> dict[str, np.ndarray]:
    """``F`` (flicker, b = 1) and ``R`` (random walk, k = 1) for ``n`` blocks of ``block_s``, in
    Fortran order: LAPACK's, so a covariance built from them is factored in place."""
    return {
        term: np.asfortranarray(covariance_term(term)[0](n, block_s, duration_s)) for term in COVARIANCE_NOISE
    }


@dataclass(frozen=True)
class NoiseState:
    """Which correlated noise terms are in the model and their ratios to the white variance."""

    terms: tuple[str, ...]
    log_ratios: tuple[float, ...]

    def ratios(self) -> dict[str, float]:
        return {term: 10.0**lr for term, lr in zip(self.terms, self.log_ratios, strict=True)}


class Gls:
    """A Cholesky-factored block covariance (up to the profiled scale ``s^2``)."""

    def __init__(
        self, n: int, block_s: float, duration_s: float, state: NoiseState, held_out: np.ndarray | None = None
    ) -> None:
        self.n = n
        self.held_out = held_out
        self.block_s = block_s
        self.duration_s = duration_s
        self.state = state
        self.n_weighted = n - (0 if held_out is None else int(np.sum(held_out)))
        # factored in place (Fortran order, as LAPACK reads it): the same numbers as from a copy of a
        # C-ordered matrix, without the copy; the covariance is rebuilt when asked for (cov_unit)
        chol, info = dpotrf(self._unit_covariance(), lower=1, clean=1, overwrite_a=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"noise covariance not positive definite (dpotrf info {info})")
        self.chol = chol  # lower triangular (the upper triangle zeroed)
        diag = np.diag(chol)
        self.half_logdet = float(np.sum(np.log(diag if held_out is None else diag[~held_out])))
        self._whitened_source: np.ndarray | None = None
        self._whitened: np.ndarray | None = None

    def _unit_covariance(self) -> np.ndarray:
        """``I + sum(ratio * unit matrix)`` (Fortran order, as the unit matrices)."""
        n, held_out = self.n, self.held_out
        units = unit_matrices(n, self.block_s, self.duration_s) if self.state.terms else {}
        cov: np.ndarray | None = None
        for term, ratio in self.state.ratios().items():
            if cov is None:
                cov = units[term] * ratio
            else:
                cov += units[term] * ratio
        if cov is None:
            cov = np.zeros((n, n), order="F")
        cov[np.diag_indices(n)] += 1.0
        if held_out is not None:
            # a held-out block's variance so large that its (imputed) value carries no weight; the
            # likelihood then counts the other blocks only (the constant log-det term cancels below)
            cov[np.flatnonzero(held_out), np.flatnonzero(held_out)] += HELD_OUT_VARIANCE
        return cov

    @property
    def cov_unit(self) -> np.ndarray:
        """The block covariance up to the profiled scale ``s^2`` (rebuilt: the factor overwrote it)."""
        return self._unit_covariance()

    def whiten(self, m: np.ndarray) -> np.ndarray:
        return solve_triangular(self.chol, m, lower=True, check_finite=False)

    def whiten_data(self, y: np.ndarray) -> np.ndarray:
        """``whiten(y)``, kept for the last ``y`` object: a model search whitens the same block
        means at every evaluation of one factor (the result is the same array, bit for bit)."""
        if y is not self._whitened_source:
            self._whitened, self._whitened_source = self.whiten(y), y
        assert self._whitened is not None
        return self._whitened

    def fit(self, X: np.ndarray, y: np.ndarray, *, reml: bool = False) -> GlsResult:
        """GLS coefficients and the profiled log-likelihood of ``y = X beta + e`` (and the restricted
        one when ``reml``: only the noise fit reads it, and it costs a QR)."""
        return self.fit_whitened(self.whiten(X), self.whiten_data(y), reml=reml)

    def fit_whitened(self, Xw: np.ndarray, yw: np.ndarray, *, reml: bool = False) -> GlsResult:
        if Xw.shape[1]:
            beta, *_ = np.linalg.lstsq(Xw, yw, rcond=None)
            rw = yw - Xw @ beta
        else:
            beta = np.zeros(0)
            rw = yw
        rss = float(rw @ rw)
        restricted = self._reml(Xw, rss) if reml else math.nan
        return GlsResult(beta=beta, rss=rss, loglik=self.loglik_from_rss(rss), reml=restricted)

    def _reml(self, Xw: np.ndarray, rss: float) -> float:
        """Restricted likelihood: the noise seen after the regressors took their share. ML variance
        estimates are biased low when slow regressors (the polynomial) absorb part of a random walk."""
        p = Xw.shape[1]
        if p == 0:
            return self.loglik_from_rss(rss)
        diag = np.abs(np.diag(np.linalg.qr(Xw, mode="r")))
        rank = int(np.sum(diag > 1e-10 * max(float(diag.max()), 1e-300)))
        logdet_xtx = 2.0 * float(np.sum(np.log(diag[diag > 1e-10 * max(float(diag.max()), 1e-300)])))
        dof = self.n_weighted - rank
        s2 = max(rss / dof, 1e-300)
        return -0.5 * dof * (math.log(2.0 * math.pi * s2) + 1.0) - self.half_logdet - 0.5 * logdet_xtx

    def loglik_from_rss(self, rss: float) -> float:
        n = self.n_weighted
        s2 = max(rss / n, 1e-300)
        return -0.5 * n * (math.log(2.0 * math.pi * s2) + 1.0) - self.half_logdet

    def noise_params(self, rss: float) -> dict[str, float]:
        """Catalogue noise coefficients implied by the fitted scale and ratios."""
        s2 = rss / self.n_weighted
        out = {WHITE_NOISE: math.sqrt(s2 * self.block_s)}
        ratios = self.state.ratios()
        for term in COVARIANCE_NOISE:
            if term in ratios:
                out[term] = math.sqrt(ratios[term] * s2)
        return out


@dataclass(frozen=True)
class GlsResult:
    beta: np.ndarray
    rss: float
    loglik: float  # ML, scale profiled: what the BIC uses
    reml: float  # restricted likelihood: what the noise ratios are estimated by (nan: not asked for)


def initial_state(terms: Sequence[str], block_s: float, white_n: float) -> NoiseState:
    """Starting ratios: b and k of the simulator's defaults relative to the measured white noise."""
    s2 = max(white_n, 1e-6) ** 2 / block_s
    guess = {term: covariance_term(term)[1] ** 2 / s2 for term in COVARIANCE_NOISE}
    logs = tuple(float(np.clip(math.log10(guess[t]), *LOG_RATIO_BOUNDS)) for t in terms)
    return NoiseState(tuple(terms), logs)


def fit_noise(
    X: np.ndarray,
    y: np.ndarray,
    n: int,
    block_s: float,
    duration_s: float,
    start: NoiseState,
    *,
    max_evals: int = 30,
    explore: bool = True,
    held_out: np.ndarray | None = None,
) -> tuple[Gls, GlsResult]:
    """Noise ratios for the linear model ``X`` by restricted maximum likelihood (REML).

    REML, not ML: the polynomial and the effect columns absorb part of a slow random walk, and ML
    would give back a walk coefficient biased low. Returns the factor and the fit at those ratios
    (whose ``loglik`` is the ML value the BIC uses).
    """
    if not start.terms:
        gls = Gls(n, block_s, duration_s, start, held_out)
        return gls, gls.fit(X, y, reml=True)
    cache: dict[tuple[float, ...], tuple[Gls, GlsResult]] = {}

    def evaluate(logs: np.ndarray) -> tuple[Gls, GlsResult]:
        key = tuple(np.round(np.clip(logs, *LOG_RATIO_BOUNDS), 4))
        if key not in cache:
            gls = Gls(n, block_s, duration_s, NoiseState(start.terms, key), held_out)
            cache[key] = (gls, gls.fit(X, y, reml=True))
        return cache[key]

    x0 = np.array(start.log_ratios)
    # A grid of whole decades around the start first: the likelihood of variance ratios has flat
    # ridges, and a Nelder-Mead started on one stops there. Comparing two models by BIC is only
    # fair if both noise fits reached their optimum, so every fit explores.
    span = (-2.0, -1.0, 0.0, 1.0, 2.0) if explore else (-1.0, 0.0, 1.0)
    best = x0
    best_ll = evaluate(x0)[1].reml
    for offsets in itertools.product(span, repeat=x0.size):
        trial = np.clip(x0 + np.array(offsets), *LOG_RATIO_BOUNDS)
        ll = evaluate(trial)[1].reml
        if ll > best_ll:
            best, best_ll = trial, ll
    result = minimize(
        lambda v: -evaluate(v)[1].reml,
        best,
        method="Nelder-Mead",
        options={"xatol": 0.05, "fatol": 0.05, "maxfev": max_evals, "initial_simplex": _simplex(best)},
    )
    return evaluate(result.x if -result.fun >= best_ll else best)


def _simplex(x0: np.ndarray) -> np.ndarray:
    simplex = [x0.copy()]
    for axis in range(x0.size):
        point = x0.copy()
        point[axis] += 0.3
        simplex.append(point)
    return np.array(simplex)


def window_variances(cov: np.ndarray, width: int, step: int) -> tuple[np.ndarray, np.ndarray]:
    """Start indices and variances of the sums over windows of ``width`` under ``cov``."""
    n = cov.shape[0]
    starts = np.arange(0, n - width + 1, step)
    cum = np.zeros((n + 1, n + 1))
    cum[1:, 1:] = cov.cumsum(0).cumsum(1)
    a = starts
    b = starts + width
    var = cum[b, b] - cum[a, b] - cum[b, a] + cum[a, a]
    return starts, var
