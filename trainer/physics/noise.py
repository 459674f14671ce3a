"""The five IEEE Std 952 noise terms, each synthesised to have its Allan-deviation signature.

Every generator takes its own ``numpy.random.Generator`` (the simulator derives one per term by
SeedSequence spawning), so switching one term on never changes the noise of another.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import lru_cache

import numpy as np
from scipy.optimize import nnls
from scipy.signal import lfilter

from trainer.physics.effects import Param

NOISE_PARAMETERS: dict[str, tuple[Param, ...]] = {
    "quantization_noise": (Param("q_mg", "nonnegative"),),
    "white_noise": (Param("n_mg_rt_s", "nonnegative"),),
    "bias_instability": (Param("b_mg", "nonnegative"),),
    "rate_random_walk": (Param("k_mg_per_rt_s", "nonnegative"),),
    "rate_ramp": (Param("r_mg_per_s"),),
}

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


def noise_term(
    identifier: str, params: Mapping[str, float], n: int, dt_s: float, rng: np.random.Generator
) -> np.ndarray:
    """``n`` samples (mg) of one noise term at sample period ``dt_s``.

    - ``quantization_noise``: ``(e[k] - e[k-1]) / dt`` with ``e`` uniform white of standard
      deviation ``q`` (the quantisation error of the integrated output, in mg s); its Allan
      deviation is exactly ``sqrt(3) q / tau``.
    - ``white_noise``: Gaussian, standard deviation ``n / sqrt(dt)``.
    - ``bias_instability``: the Gauss-Markov bank of :func:`bias_instability_bank`.
    - ``rate_random_walk``: cumulative sum of Gaussian steps of ``k sqrt(dt)``, starting at 0.
    - ``rate_ramp``: the deterministic ramp ``r t`` (IEEE 952 treats it as a trend); no randomness.
    """
    if identifier == "quantization_noise":
        q = params["q_mg"]
        e = rng.uniform(-math.sqrt(3.0) * q, math.sqrt(3.0) * q, n + 1)
        return np.diff(e) / dt_s
    if identifier == "white_noise":
        return rng.standard_normal(n) * (params["n_mg_rt_s"] / math.sqrt(dt_s))
    if identifier == "bias_instability":
        b = params["b_mg"]
        tcs, variances = bias_instability_bank(float(dt_s), max(BI_FLAT_UNTIL_S, n * dt_s))
        out = np.zeros(n)
        for tc, var in zip(tcs, variances, strict=True):
            out += gauss_markov(n, dt_s, float(tc), b * math.sqrt(var), rng)
        return out
    if identifier == "rate_random_walk":
        steps = rng.standard_normal(n) * (params["k_mg_per_rt_s"] * math.sqrt(dt_s))
        steps[0] = 0.0
        return np.cumsum(steps)
    if identifier == "rate_ramp":
        return params["r_mg_per_s"] * (np.arange(n) * dt_s)
    raise ValueError(f"unknown noise identifier {identifier!r}")
