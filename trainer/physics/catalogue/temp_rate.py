"""``temp_rate``: thermal-gradient stress, ``k * dT_die/dt`` (degC/min)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from trainer.physics.catalogue import rules
from trainer.physics.catalogue.base import (
    BlockDesign,
    Effect,
    Finder,
    Param,
    Scenario,
    Signals,
    rate_c_per_min,
)


def rate_term(rate_c_per_min: np.ndarray, k_mg_per_c_per_min: float) -> np.ndarray:
    return k_mg_per_c_per_min * np.asarray(rate_c_per_min, dtype=np.float64)


def _contribution(p: Mapping[str, float], s: Signals) -> np.ndarray:
    rate = rate_c_per_min(s.t, s.T_die) if s.rate_c_per_min is None else s.rate_c_per_min
    return rate_term(rate, p["k_mg_per_c_per_min"])


def _columns(term: Any, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    return [("k_mg_per_c_per_min", d.rate)]


DEFINITION = Effect(
    identifier="temp_rate",
    compensable=True,
    params=(Param("k_mg_per_c_per_min", unit="mg per degC/min", plausible=(0.01, 2.0)),),
    summary="k * dT_die/dt (thermal-gradient stress, dT/dt in degC/min)",
    contribution=_contribution,
    finder=Finder(
        search="linear",
        columns=_columns,
        identifiability=rules.rate_changes,
        advice=(
            "the bias depends on dT/dt (thermal-gradient stress): a polynomial calibrated at one rate is off "
            "at another; add a dT/dt input or calibrate at the flight's heating rates"
        ),
        confounders=("thermal_lag", "hysteresis", "stress_relaxation"),
        separations={
            "hysteresis": (
                "a dT/dt offset vanishes in a hold and scales with the rate; a hysteresis offset persists"
            ),
            "stress_relaxation": (
                "on ramps both give an offset that follows the rate; a dT/dt term vanishes as soon as the "
                "temperature stops, creep keeps settling for tens of minutes in a hold"
            ),
        },
    ),
    scenario=Scenario(
        draw=lambda rng, duration, sign: {"k_mg_per_c_per_min": sign * float(rng.uniform(0.04, 0.2))},
        checked=("k_mg_per_c_per_min",),
    ),
)
