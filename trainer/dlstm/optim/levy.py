"""Lévy-flight steps by Mantegna's method (Guo et al. 2023, eq. (14)-(15)).

ISSA replaces the Gaussian jump ``Q`` of the sparrow search with a Lévy step so that
producers in danger and starving scroungers occasionally make very long jumps (heavy
tail) while most jumps stay short.  Mantegna's algorithm produces such steps from two
Gaussians::

    LF    = sigma * N / |M| ** (1 / beta)                                    (14)
    sigma = [Gamma(1 + beta) sin(pi beta / 2)
             / (beta Gamma((1 + beta) / 2) 2 ** ((beta - 1) / 2))] ** (1 / beta)   (15)

with ``N, M ~ N(0, 1)`` independent.  ``P(|LF| > x)`` decays like ``x ** -beta`` for
large ``x`` (because ``P(|M| < e) ~ 2 e / sqrt(2 pi)`` for small ``e``), i.e. the tail
index is ``beta``, as for an alpha-stable law with ``alpha = beta``.  The tests check
this tail, the symmetry and the hand value ``sigma(1.5) ~= 0.6966``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["levy_step", "mantegna_sigma"]


def mantegna_sigma(beta: float = 1.5) -> float:
    """Scale of the numerator Gaussian in Mantegna's method, eq. (15)."""
    if not 0.0 < beta < 2.0:
        # beta = 2 gives sin(pi) = 0, i.e. sigma = 0 and no steps at all.
        raise ValueError(f"beta must lie in (0, 2), got {beta}")
    numerator = math.gamma(1.0 + beta) * math.sin(math.pi * beta / 2.0)
    denominator = beta * math.gamma((1.0 + beta) / 2.0) * 2.0 ** ((beta - 1.0) / 2.0)
    return (numerator / denominator) ** (1.0 / beta)


def levy_step(rng: np.random.Generator, size: int | tuple[int, ...], beta: float = 1.5) -> np.ndarray:
    """Draw symmetric heavy-tailed Lévy steps of the given shape, eq. (14).

    The numerator Gaussians are drawn first, then the denominator ones, so a given
    generator state always yields the same steps.
    """
    sigma = mantegna_sigma(beta)
    numerator = sigma * rng.standard_normal(size)
    denominator = np.abs(rng.standard_normal(size)) ** (1.0 / beta)
    return numerator / denominator
