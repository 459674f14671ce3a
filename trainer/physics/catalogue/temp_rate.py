"""``temp_rate``: thermal-gradient stress, ``k * LP(dT_die/dt, tau_s)`` (degC/min).

With ``tau_s > 0`` the low-passed rate is computed as ``(T_die - LP(T_die, tau_s)) / tau_s``, which
is the same thing for a first-order filter (``LP(dx/dt) = d LP(x)/dt``) and needs no numerical
derivative: a compensator computes it from a noisy, quantised thermometer exactly this way.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping

import numpy as np

from trainer.physics.catalogue import rules
from trainer.physics.catalogue.base import (
    BlockDesign,
    Bounds,
    Effect,
    Finder,
    FinderData,
    FinderTerm,
    Param,
    Scenario,
    Signals,
    StartContext,
    StartingTerm,
    rate_c_per_min,
    sample_period,
)
from trainer.physics.catalogue.thermal_lag import DEFINITION as THERMAL_LAG
from trainer.physics.thermal import lowpass

FREED_MAX_S = 120.0  # the longest filter the finder proposes freed on a run that never holds after a ramp
TAU_MAX_S = 600.0  # the catalogue's longest filter (``tau_s`` plausible and searched)
HOLD_PER_TAU = 3.0  # a hold after a ramp shows a filter's decay over three time constants (95 %)


def freed_max_s(hold_after_ramp_s: float) -> float:
    """The longest filter a run resolves: :data:`FREED_MAX_S`, or up to the catalogue's 600 s where
    a hold after a ramp lasts :data:`HOLD_PER_TAU` time constants.

    On continuous ramps a rate term through a long filter takes the run's own heating/cooling loop,
    as a thermal lag or a branch offset would (the bundled real run, no hold: with 600 s the bench
    lost 4 clean findings and named 3 rate terms it was not given). In a hold the filtered rate
    decays with its own time constant, which pins it: the realistic experiment's gyroscope (holds of
    1021-1534 s after ramps) carries a rate term through 330 s that a 120 s cap leaves to an
    implausible creep.
    """
    return min(TAU_MAX_S, max(FREED_MAX_S, hold_after_ramp_s / HOLD_PER_TAU))


def _freed_bounds(data: FinderData, present: Collection[str]) -> Bounds:
    """One block to :data:`FREED_MAX_S`; beside a thermal lag, to what the run resolves.

    Alone, a rate term through a filter of the lag's time constant is the lag on a straight bias
    curve (the lagged polynomial is the polynomial minus its slope times ``tau`` times the filtered
    rate): a lag of 176 s beside an instantaneous rate term was named as one rate term through 219 s,
    k six times too large. The lag, the first physics of a thermometer apart from the die, is named
    first; a long filter then explains only what the lag leaves.
    """
    hi = freed_max_s(data.hold_after_ramp_s) if THERMAL_LAG.identifier in present else FREED_MAX_S
    return ((data.block_s, hi),)


def rate_term(rate_c_per_min: np.ndarray, k_mg_per_c_per_min: float) -> np.ndarray:
    return k_mg_per_c_per_min * np.asarray(rate_c_per_min, dtype=np.float64)


def filtered_rate(T: np.ndarray, tau_s: float, dt_s: float) -> np.ndarray:
    """``LP(dT/dt, tau_s)`` in degC/min as ``60 (T - LP(T, tau_s)) / tau_s`` (no derivative taken)."""
    T = np.asarray(T, dtype=np.float64)
    return 60.0 * (T - lowpass(T, tau_s, dt_s)) / tau_s


def _contribution(p: Mapping[str, float], s: Signals) -> np.ndarray:
    tau = p.get("tau_s", 0.0)
    if tau > 0:
        return rate_term(filtered_rate(s.T_die, tau, sample_period(s.t)), p["k_mg_per_c_per_min"])
    rate = rate_c_per_min(s.t, s.T_die) if s.rate_c_per_min is None else s.rate_c_per_min
    return rate_term(rate, p["k_mg_per_c_per_min"])


def _columns(term: FinderTerm, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    tau = term.nl[0] if term.nl else 0.0
    if tau > 0:
        return [("k_mg_per_c_per_min", filtered_rate(d.T, tau, d.data.block_s))]
    return [("k_mg_per_c_per_min", d.rate)]


def _to_params(term: FinderTerm, linear: Mapping[str, float]) -> dict[str, float]:
    """The instantaneous form (``tau_s = 0``, the default) is written without ``tau_s``."""
    params = {"k_mg_per_c_per_min": linear["k_mg_per_c_per_min"]}
    if term.nl and term.nl[0] > 0:
        params["tau_s"] = float(term.nl[0])
    return params


def _from_config(params: Mapping[str, float], context: StartContext) -> StartingTerm:
    """A configured ``tau_s`` is refined; the instantaneous form stays instantaneous."""
    tau = float(params.get("tau_s", 0.0))
    return StartingTerm((tau,), fixed=tau == 0.0)


DEFINITION = Effect(
    identifier="temp_rate",
    compensable=True,
    params=(
        Param("k_mg_per_c_per_min", unit="mg per degC/min", plausible=(0.01, 2.0)),
        Param("tau_s", "nonnegative", default=0.0, unit="s", plausible=(0.0, TAU_MAX_S)),
    ),
    summary="k * LP(dT_die/dt, tau_s) (thermal-gradient stress, dT/dt in degC/min; tau_s = 0: instantaneous)",
    contribution=_contribution,
    finder=Finder(
        # Proposed instantaneous (tau_s held at 0, linear) and with tau_s freed, the better by BIC;
        # a configured or compensator-refined tau_s is searched on a linear scale, so that 0 stays
        # reachable.
        search="linear",
        nonlinear=(("tau_s", False),),
        bounds=lambda data: ((0.0, TAU_MAX_S),),
        # Freed: from one block (the blocks cannot resolve a shorter filter: the instantaneous form
        # stands) to what the run's holds after ramps resolve (freed_max_s).
        freed_bounds=_freed_bounds,
        grid_points=6,
        columns=_columns,
        to_params=_to_params,
        from_config=_from_config,
        identifiability=rules.rate_changes,
        advice=(
            "the bias depends on dT/dt (thermal-gradient stress): a polynomial calibrated at one rate is off "
            "at another; add a dT/dt input or calibrate at the flight's heating rates"
        ),
        confounders=("thermal_lag", "hysteresis", "stress_relaxation", "bias_step", "warmup"),
        separations={
            "bias_step": (
                "at a ramp reversal a dT/dt offset jumps by k times the change of rate, as a step would; a "
                "step stays when the temperature settles, a dT/dt offset vanishes (a hold after the reversal)"
            ),
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
