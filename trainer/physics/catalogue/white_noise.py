"""``white_noise``: Gaussian, Allan slope -1/2, ``sigma = n / sqrt(tau)``."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue.base import Finder, NoiseTerm, Param, Scenario


def synthesize(p: Mapping[str, float], n: int, dt_s: float, rng: np.random.Generator) -> np.ndarray:
    """Gaussian, standard deviation ``n / sqrt(dt)``."""
    return rng.standard_normal(n) * (p["n_mg_rt_s"] / math.sqrt(dt_s))


DEFINITION = NoiseTerm(
    identifier="white_noise",
    params=(Param("n_mg_rt_s", "nonnegative", unit="mg s^1/2"),),
    summary="slope -1/2, sigma = n / sqrt(tau), read at tau = 1",
    synthesize=synthesize,
    finder=Finder(
        # always fitted: from the full-rate first differences (on block means it is barely
        # separable from flicker; at the sample rate it dominates)
        noise_role="white",
        allan_variance=lambda taus, dt, duration_s, p: p["n_mg_rt_s"] ** 2 / taus,
        missing_note="the simulation has no white_noise; every sensor has some, so it is always fitted",
    ),
    scenario=Scenario(known=lambda rng: {"n_mg_rt_s": float(rng.uniform(0.02, 0.08))}),
)
