"""``thermal_lag``: the proof mass lags the thermometer, ``T_pm = LP(T_die, tau_s)``."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue import rules
from trainer.physics.catalogue.base import Effect, Finder, Param, Scenario, sample_period
from trainer.physics.thermal import lowpass


def proof_mass(t: np.ndarray, T_die: np.ndarray, p: Mapping[str, float]) -> np.ndarray:
    return lowpass(T_die, p["tau_s"], sample_period(np.asarray(t)))


DEFINITION = Effect(
    identifier="thermal_lag",
    compensable=True,
    params=(Param("tau_s", "positive", unit="s", plausible=(10.0, 900.0)),),
    summary="T_pm = LP(T_die, tau_s): the proof mass lags the thermometer",
    proof_mass=proof_mass,
    finder=Finder(
        search="profile",
        nonlinear=(("tau_s", True),),
        bounds=lambda data: ((3.0, 1500.0),),
        grid_points=18,
        proof_mass=lambda term, T, block_s: lowpass(T, term.nl[0], block_s),
        identifiability=rules.rate_changes,
        advice=(
            "the proof mass lags the thermometer: a polynomial fitted at one heating rate is skewed when the "
            "rate changes (uneven heating on the pad or in flight); feed the compensator a low-passed temperature"
        ),
        confounders=("temp_rate", "hysteresis", "stress_relaxation", "temp_quantization"),
        separations={
            "temp_rate": (
                "a lag scales with the local slope of the bias curve and settles with its own time constant "
                "after a ramp corner; a dT/dt term follows the rate itself (two ramp rates or a hold separate them)"
            ),
            "hysteresis": (
                "a lag offset decays during a hold and grows with the ramp rate; a hysteresis offset "
                "persists in a hold and does not depend on the rate"
            ),
            "stress_relaxation": (
                "the time constant: a lag settles within minutes (10-900 s), package creep over 20 min to hours"
            ),
            "temp_quantization": (
                "a staircase error is a sawtooth of one LSB period on every ramp and an unknown offset in holds; "
                "a lag offset is proportional to the rate (a finer thermometer reading settles it)"
            ),
        },
    ),
    scenario=Scenario(
        draw=lambda rng, duration, sign: {"tau_s": float(rng.uniform(60.0, 400.0))},
        checked=("tau_s",),
    ),
)
