"""``warmup``: self-heating after power-on, ``amp * exp(-t / tau_s)``."""

from __future__ import annotations

import math
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
    Region,
    Scenario,
    WhereContext,
)
from trainer.physics.catalogue.bias_poly import absorbed_fraction

WARMUP_TIME_CONSTANTS = 3.0  # the part of the run a warm-up is located in
TAU_PLAUSIBLE_S = (60.0, 1800.0)
ABSORPTION_TAUS = 8  # time constants over the plausible range tested against the bias polynomial
ABSORBED = 0.95  # share of a warm-up a cubic in temperature absorbs at which it cannot be named


def settling(t: np.ndarray, amp_mg: float, tau_s: float) -> np.ndarray:
    return amp_mg * np.exp(-t / tau_s)


def _columns(term: FinderTerm, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    tau = term.nl[0]
    x = d.data.block_s / (2.0 * tau)  # exact block mean of the exponential
    return [("amp_mg", np.exp(-d.data.t / tau) * (math.sinh(x) / x if x > 1e-8 else 1.0))]


def absorbed_taus(t_s: np.ndarray, temp_c: np.ndarray) -> list[float]:
    """Plausible time constants whose warm-up a cubic in temperature absorbs (>= ``ABSORBED``): on a
    start the run never returns to, the warm-up is a function of temperature there."""
    taus = np.geomspace(*TAU_PLAUSIBLE_S, ABSORPTION_TAUS)
    return [float(tau) for tau in taus if absorbed_fraction(temp_c, np.exp(-t_s / tau)) >= ABSORBED]


def _identifiability(p: FinderProfile) -> Identifiability:
    """A soak at power-on shows a warm-up; without one, it must not be a function of temperature:
    when the bias cubic absorbs it at most plausible time constants it cannot be named."""
    soak = bool(p.segments and p.segments[0].label == "soak")
    absorbed = [] if soak or p.block_t_s.size < 8 else absorbed_taus(p.block_t_s, p.block_temp_c)
    test = "power on and soak 30 min before ramping, or return to the starting temperature later"
    confounded = (
        f"a cubic in temperature absorbs >= {100 * ABSORBED:g} % of a warm-up with a time constant of "
        f"{min(absorbed, default=0):.0f}..{max(absorbed, default=0):.0f} s: there it is confounded with "
        "the bias polynomial"
    )
    if 2 * len(absorbed) >= ABSORPTION_TAUS:
        return Identifiability(False, f"the run starts on a ramp it does not return to; {confounded}", test)
    if absorbed:
        return Identifiability(
            True, f"the recording starts at power-on (no soak); {confounded}", test, weak=True
        )
    return Identifiability(
        True,
        "the recording starts at power-on" + ("" if soak else " (no soak)"),
        "" if soak else "power on and soak 30 min before ramping",
        weak=not soak,
    )


def _where(p: Mapping[str, float], ctx: WhereContext) -> list[Region]:
    """The first three time constants after power-on."""
    data = ctx.data
    b = int(np.clip(np.searchsorted(data.starts, WARMUP_TIME_CONSTANTS * p["tau_s"]), 2, data.n))
    return [ctx.region(0, b, {"z": ctx.window_z(0, b)}, "effect", "first three warm-up time constants")]


DEFINITION = Effect(
    identifier="warmup",
    compensable=True,
    params=(
        Param("amp_mg", unit="mg", plausible=(0.05, 5.0)),
        Param("tau_s", "positive", unit="s", plausible=TAU_PLAUSIBLE_S),
    ),
    summary="amp * exp(-t / tau_s) (self-heating after power-on)",
    contribution=lambda p, s: settling(s.t, p["amp_mg"], p["tau_s"]),
    finder=Finder(
        search="profile",
        nonlinear=(("tau_s", True),),
        bounds=lambda data: ((max(5.0, 2.0 * data.block_s), max(60.0, min(6000.0, 0.5 * data.duration_s))),),
        grid_points=16,
        columns=_columns,
        where=_where,
        identifiability=_identifiability,
        advice=(
            "self-heating after power-on: the bias settles over the first minutes; let the board warm up "
            "(about 3 time constants) before calibration and before flight, or model the warm-up"
        ),
        # on a ramp that starts from a soak, a dT/dt offset (through the case's lag) rises as
        # amp (1 - exp(-t / tau)): a warm-up's shape on the polynomial's constant (a walk-through named a
        # warm-up in place of a concealed rate term there)
        confounders=("stress_relaxation", "bias_step", "temp_rate"),
        separations={
            "temp_rate": (
                "a ramp that starts from a soak lifts a dT/dt offset as a warm-up settles; a warm-up decays "
                "from power-on whatever the temperature does, a dT/dt offset follows the rate (power on "
                "and soak before ramping, or a second ramp at another rate)"
            ),
        },
    ),
    scenario=Scenario(
        draw=lambda rng, duration, sign: {
            "amp_mg": sign * float(rng.uniform(0.5, 1.2)),
            "tau_s": float(rng.uniform(200.0, 900.0)),
        },
        checked=("amp_mg", "tau_s"),
    ),
)
