"""``bias_instability``: flicker, a flat Allan floor ``sigma_min = 0.664 b``.

Synthesised as a sum of first-order Gauss-Markov processes with log-spaced time constants whose
variances make the exact discrete Allan variance flat (see :func:`bias_instability_bank`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import lru_cache

import numpy as np
from scipy.linalg import toeplitz
from scipy.optimize import nnls
from scipy.signal import lfilter

from trainer.physics.catalogue import rules
from trainer.physics.catalogue.base import Finder, NoiseTerm, Param, Scenario

# Flicker floor of the Allan variance for b = 1: sigma_min^2 = (2 ln 2 / pi) b^2, i.e. 0.664 b.
FLICKER_FLOOR_VAR = 2.0 * math.log(2.0) / math.pi
BI_FLAT_UNTIL_S = 1.0e4  # the floor is flat from one sample period to max(this, recording length)
BI_PROCESSES_PER_DECADE = 2.0


def ar1_allan_variance(m: np.ndarray, dt_s: float, tc_s: float) -> np.ndarray:
    """Exact Allan variance at ``tau = m dt`` of a unit-variance sampled AR(1) (Gauss-Markov).

    With ``u = 1 - a``, ``a = exp(-dt/tc)``, ``A = 1 - a^m`` (cluster means of m samples):
    ``sigma^2 m^2 = m + (2a(m u - A) - a A^2) / u^2``. Written with expm1/log1p so that it stays
    accurate (relative error ~ eps / u) for time constants far longer than the sample period.
    """
    m = np.asarray(m, dtype=np.float64)
    u = -math.expm1(-dt_s / tc_s)
    a = 1.0 - u
    big_a = -np.expm1(m * math.log1p(-u))
    bracket = m + (2.0 * a * (m * u - big_a) - a * big_a * big_a) / (u * u)
    return bracket / (m * m)


@lru_cache(maxsize=32)
def bias_instability_bank(dt_s: float, flat_until_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Time constants (s) and variances (per unit ``b^2``) of the Gauss-Markov sum for flicker.

    Time constants are log-spaced, two per decade, from one sample period to three times
    ``flat_until_s``. The variances are the non-negative least-squares solution that makes the
    summed Allan variance equal ``(0.664 b)^2`` on a log grid of ``tau`` from ``dt`` to
    ``flat_until_s``; the result is flat to about +/-1 % over that range.
    """
    ratio = 10.0 ** (1.0 / BI_PROCESSES_PER_DECADE)
    count = 1 + math.ceil(math.log(3.0 * flat_until_s / dt_s) / math.log(ratio))
    time_constants = dt_s * ratio ** np.arange(count)
    m_max = max(2.0, flat_until_s / dt_s)
    ms = np.unique(np.round(np.logspace(0.0, math.log10(m_max), 160)))
    design = np.column_stack([ar1_allan_variance(ms, dt_s, tc) for tc in time_constants])
    variances, _ = nnls(design / FLICKER_FLOOR_VAR, np.ones(ms.size))
    keep = variances > 0
    return time_constants[keep], variances[keep]


def bias_instability_allan_variance(tau_s: np.ndarray, dt_s: float, flat_until_s: float) -> np.ndarray:
    """Designed (expected) Allan variance of the bias-instability generator, per unit ``b^2``."""
    m = np.asarray(tau_s, dtype=np.float64) / dt_s
    tcs, variances = bias_instability_bank(dt_s, flat_until_s)
    return sum(v * ar1_allan_variance(m, dt_s, tc) for tc, v in zip(tcs, variances, strict=True))


def gauss_markov(n: int, dt_s: float, tc_s: float, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Stationary first-order Gauss-Markov: ``x[k] = a x[k-1] + sigma sqrt(1-a^2) w[k]``."""
    a = math.exp(-dt_s / tc_s)
    drive = rng.standard_normal(n)
    drive[1:] *= sigma * math.sqrt(-math.expm1(-2.0 * dt_s / tc_s))
    drive[0] *= sigma  # x[0] drawn from the stationary distribution
    return lfilter([1.0], [1.0, -a], drive)


def synthesize(p: Mapping[str, float], n: int, dt_s: float, rng: np.random.Generator) -> np.ndarray:
    """The Gauss-Markov bank of :func:`bias_instability_bank`."""
    b = p["b_mg"]
    tcs, variances = bias_instability_bank(float(dt_s), max(BI_FLAT_UNTIL_S, n * dt_s))
    out = np.zeros(n)
    for tc, var in zip(tcs, variances, strict=True):
        out += gauss_markov(n, dt_s, float(tc), b * math.sqrt(var), rng)
    return out


def block_covariance(n: int, block_s: float, duration_s: float) -> np.ndarray:
    """Covariance of ``n`` block means for ``b = 1``: the bank sampled at the block period."""
    tcs, variances = bias_instability_bank(float(block_s), max(BI_FLAT_UNTIL_S, float(duration_s)))
    lags = np.arange(n, dtype=np.float64)
    row = np.zeros(n)
    for tc, var in zip(tcs, variances, strict=True):
        row += var * np.exp(-lags * block_s / tc)
    return toeplitz(row)


def allan_variance(taus: np.ndarray, dt: float, duration_s: float, p: Mapping[str, float]) -> np.ndarray:
    """Modelled Allan variance: the designed curve of the generator (the floor when ``dt > 1 s``)."""
    var = np.zeros_like(taus, dtype=np.float64)
    b = p["b_mg"]
    if b > 0:
        flat = max(BI_FLAT_UNTIL_S, duration_s)
        if dt <= 1.0:
            var += b * b * bias_instability_allan_variance(taus, dt, flat)
        else:
            var += b * b * FLICKER_FLOOR_VAR
    return var


DEFINITION = NoiseTerm(
    identifier="bias_instability",
    params=(Param("b_mg", "nonnegative", unit="mg"),),
    summary="flat floor, sigma_min = 0.664 b, read at the minimum",
    synthesize=synthesize,
    finder=Finder(
        search="noise",
        noise_role="covariance",
        covariance=block_covariance,
        start_coefficient=0.02,
        allan_variance=allan_variance,
        identifiability=rules.whole_run,
        advice="flicker noise floor beyond the modelled noise",
    ),
    scenario=Scenario(known=lambda rng: {"b_mg": float(rng.uniform(0.008, 0.025))}),
)
