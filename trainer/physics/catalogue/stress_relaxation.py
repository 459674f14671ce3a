"""``stress_relaxation``: package creep, ``gain * (T_die - LP(T_die, tau_s))``."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue.base import (
    BlockDesign,
    Effect,
    Finder,
    FinderProfile,
    FinderTerm,
    Identifiability,
    Param,
    Scenario,
    Signals,
    sample_period,
)
from trainer.physics.thermal import lowpass


def creep(T_die: np.ndarray, gain_mg_per_c: float, tau_s: float, dt_s: float) -> np.ndarray:
    return gain_mg_per_c * (T_die - lowpass(T_die, tau_s, dt_s))


def _contribution(p: Mapping[str, float], s: Signals) -> np.ndarray:
    return creep(s.T_die, p["gain_mg_per_c"], p["tau_s"], sample_period(s.t))


def _columns(term: FinderTerm, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    return [("gain_mg_per_c", d.T - lowpass(d.T, term.nl[0], d.data.block_s))]


def _identifiability(p: FinderProfile) -> Identifiability:
    if p.duration_s >= 1200.0 and (p.holds_after_ramp_s >= 600.0 or p.reversals >= 1):
        return Identifiability(
            True,
            f"longest hold after a ramp {p.holds_after_ramp_s:.0f} s, {p.reversals} reversal(s)",
            "" if p.holds_after_ramp_s >= 1800 else "hold >= 1 h after the ramp to see the creep settle",
            weak=p.holds_after_ramp_s < 1800,
        )
    return Identifiability(
        False,
        "no hold after a ramp or reversal long enough for a 20-min-plus creep to show apart from the polynomial",
        "hold the temperature for >= 1 h after the ramp",
    )


DEFINITION = Effect(
    identifier="stress_relaxation",
    compensable=True,
    params=(
        Param("gain_mg_per_c", unit="mg/degC", plausible=(0.001, 0.05)),
        Param("tau_s", "positive", unit="s", plausible=(1200.0, 20000.0)),
    ),
    summary="gain * (T_die - LP(T_die, tau_s)) (package creep)",
    contribution=_contribution,
    finder=Finder(
        search="profile",
        nonlinear=(("tau_s", True),),
        bounds=lambda data: ((600.0, max(1200.0, min(40000.0, 4.0 * data.duration_s))),),
        grid_points=12,
        columns=_columns,
        identifiability=_identifiability,
        advice=(
            "package creep after a temperature change: the bias keeps moving for tens of minutes at a constant "
            "temperature; hold long enough before calibrating or model the creep"
        ),
        confounders=("thermal_lag", "temp_rate", "warmup", "hysteresis_offset"),
        separations={"warmup": "creep follows each temperature change; warm-up happens once after power-on"},
    ),
    scenario=Scenario(
        draw=lambda rng, duration, sign: {
            "gain_mg_per_c": sign * float(rng.uniform(0.012, 0.03)),
            "tau_s": float(rng.uniform(1500.0, 4000.0)),
        },
        checked=("gain_mg_per_c", "tau_s"),
        long_holds=True,
    ),
)
