"""The five IEEE Std 952 noise terms, each synthesised to have its Allan-deviation signature.

Each term's parameters and generator live in its module of :mod:`trainer.physics.catalogue`.
Every generator takes its own ``numpy.random.Generator`` (the simulator derives one per term by
SeedSequence spawning), so switching one term on never changes the noise of another.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue import NOISE, NOISE_PARAMETERS
from trainer.physics.catalogue.bias_instability import (
    BI_FLAT_UNTIL_S,
    BI_PROCESSES_PER_DECADE,
    FLICKER_FLOOR_VAR,
    ar1_allan_variance,
    bias_instability_allan_variance,
    bias_instability_bank,
    gauss_markov,
)

__all__ = [
    "BI_FLAT_UNTIL_S",
    "BI_PROCESSES_PER_DECADE",
    "FLICKER_FLOOR_VAR",
    "NOISE_PARAMETERS",
    "ar1_allan_variance",
    "bias_instability_allan_variance",
    "bias_instability_bank",
    "gauss_markov",
    "noise_term",
]


def noise_term(
    identifier: str, params: Mapping[str, float], n: int, dt_s: float, rng: np.random.Generator
) -> np.ndarray:
    """``n`` samples (mg) of one noise term at sample period ``dt_s`` (see the term's module)."""
    definition = NOISE.get(identifier)
    if definition is None:
        raise ValueError(f"unknown noise identifier {identifier!r}")
    return definition.synthesize(params, n, dt_s, rng)
