"""``quantization_noise``: Allan slope -1, ``sigma = sqrt(3) q / tau``."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue.base import Finder, NoiseTerm, Param


def synthesize(p: Mapping[str, float], n: int, dt_s: float, rng: np.random.Generator) -> np.ndarray:
    """``(e[k] - e[k-1]) / dt`` with ``e`` uniform white of standard deviation ``q`` (the
    quantisation error of the integrated output, in mg s): Allan deviation exactly ``sqrt(3) q / tau``."""
    q = p["q_mg"]
    e = rng.uniform(-math.sqrt(3.0) * q, math.sqrt(3.0) * q, n + 1)
    return np.diff(e) / dt_s


DEFINITION = NoiseTerm(
    identifier="quantization_noise",
    params=(Param("q_mg", "nonnegative", unit="mg"),),
    summary="slope -1, sigma = sqrt(3) q / tau, read at tau = sqrt(3)",
    synthesize=synthesize,
    finder=Finder(
        config_note="quantization_noise only shows at the shortest taus; it is not part of the drift model"
    ),
)
