"""``rate_ramp``: Allan slope +1, ``sigma = r tau / sqrt(2)``; a deterministic trend ``r t``."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue.base import (
    BlockDesign,
    Finder,
    FinderData,
    FinderProfile,
    FinderTerm,
    Identifiability,
    NoiseTerm,
    Param,
)


def synthesize(p: Mapping[str, float], n: int, dt_s: float, rng: np.random.Generator) -> np.ndarray:
    """The deterministic ramp ``r t`` (IEEE 952 treats it as a trend); no randomness."""
    return p["r_mg_per_s"] * (np.arange(n) * dt_s)


def _columns(term: FinderTerm, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    return [("r_mg_per_s", d.data.t)]


def _identifiability(p: FinderProfile) -> Identifiability:
    monotone = p.reversals == 0 and p.hold_s < 0.1 * p.duration_s
    return Identifiability(
        not monotone,
        "time and temperature move together on one ramp"
        if monotone
        else "holds or reversals decouple time from temperature",
        "add a hold or a reversal" if monotone else "",
    )


def _full_rate(lin: Mapping[str, float], data: FinderData, T_pm: np.ndarray) -> np.ndarray:
    return lin["r_mg_per_s"] * data.full_t


DEFINITION = NoiseTerm(
    identifier="rate_ramp",
    params=(Param("r_mg_per_s", unit="mg/s"),),
    summary="slope +1, sigma = r tau / sqrt(2), read at tau = sqrt(2)",
    synthesize=synthesize,
    finder=Finder(
        search="linear",
        noise_role="trend",  # a column of the drift model, reported like an effect
        columns=_columns,
        full_rate=_full_rate,  # a noise term: not in physics.effects.drift
        identifiability=_identifiability,
        advice="a linear drift in time independent of temperature (ageing, creep of the mount)",
        confounders=("rate_random_walk",),
        separations={
            "rate_random_walk": (
                "a ramp is a straight line in time; a random walk wanders (its Allan slope is +1/2, the ramp's +1)"
            )
        },
    ),
)
