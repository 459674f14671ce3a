"""``rate_random_walk``: Allan slope +1/2, ``sigma = k sqrt(tau / 3)``."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue import rules
from trainer.physics.catalogue.base import Finder, NoiseTerm, Param, Scenario


def synthesize(p: Mapping[str, float], n: int, dt_s: float, rng: np.random.Generator) -> np.ndarray:
    """Cumulative sum of Gaussian steps of ``k sqrt(dt)``, starting at 0."""
    steps = rng.standard_normal(n) * (p["k_mg_per_rt_s"] * math.sqrt(dt_s))
    steps[0] = 0.0
    return np.cumsum(steps)


def block_covariance(n: int, block_s: float, duration_s: float) -> np.ndarray:
    """Covariance of block means of a random walk of unit k started at t = 0: ``B (min(i, j) + 1/2)``
    between different blocks (the earlier block's mean time) and ``B (i + 1/3)`` on the diagonal."""
    idx = np.arange(n, dtype=np.float64)
    rw = block_s * (np.minimum.outer(idx, idx) + 0.5)
    rw[np.diag_indices(n)] = block_s * (idx + 1.0 / 3.0)
    return rw


DEFINITION = NoiseTerm(
    identifier="rate_random_walk",
    params=(Param("k_mg_per_rt_s", "nonnegative", unit="mg/s^1/2"),),
    summary="slope +1/2, sigma = k sqrt(tau / 3), read at tau = 3",
    synthesize=synthesize,
    finder=Finder(
        search="noise",
        noise_role="covariance",
        covariance=block_covariance,
        start_coefficient=5e-4,
        allan_variance=lambda taus, dt, duration_s, p: p["k_mg_per_rt_s"] ** 2 * taus / 3.0,
        identifiability=rules.whole_run,
        advice="random wander of the bias beyond the modelled noise: no compensator can remove it",
        confounders=("rate_ramp",),
    ),
    scenario=Scenario(
        draw=lambda rng, duration, sign: {"k_mg_per_rt_s": float(rng.uniform(3e-3, 6e-3))},
        checked=("k_mg_per_rt_s",),
        # a random walk needs a protocol that decouples time from temperature (else the polynomial absorbs it)
        needs_reversal=True,
        known=lambda rng: {"k_mg_per_rt_s": float(rng.uniform(2e-4, 6e-4))},
    ),
)
