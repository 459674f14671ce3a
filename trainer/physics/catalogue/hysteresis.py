"""``hysteresis``: heating and cooling branches differ by ``2 amp`` (play operator of ``T_pm``)."""

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
)
from trainer.physics.thermal import play_operator


def branch_offset(T_pm: np.ndarray, play: np.ndarray, amp_mg: float, width_c: float) -> np.ndarray:
    """``amp * (T_pm - P) / (width_c / 2)`` with ``P`` the play output of full width ``width_c``."""
    return amp_mg * (T_pm - play) / (width_c / 2.0)


def branch_contribution(p: Mapping[str, float], s: Signals) -> np.ndarray:
    """The branch term on ``T_pm`` (shared with ``hysteresis_offset``)."""
    play = play_operator(s.T_pm, p["width_c"], s.play_start_c)
    return branch_offset(s.T_pm, play, p["amp_mg"], p["width_c"])


def _columns(term: FinderTerm, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    width = term.nl[0]
    play = play_operator(d.T_pm, width)
    d.T_b = play  # the polynomial reads the play output (catalogue: T_b)
    return [("amp_mg", branch_offset(d.T_pm, play, 1.0, width))]


def reversal_identifiability(p: FinderProfile) -> Identifiability:
    """A branch offset needs both branches over a common range (shared with ``hysteresis_offset``)."""
    overlap = p.overlap_c
    if p.reversals >= 1 and overlap is not None and overlap[1] - overlap[0] >= 3.0:
        return Identifiability(
            True,
            f"heating and cooling both cover {overlap[0]:.1f}..{overlap[1]:.1f} degC",
            "" if p.holds_after_ramp_s >= 600 else "a hold at the turning point separates it from a lag",
        )
    return Identifiability(
        False,
        "no reversal of temperature over a common range: one branch cannot show a branch offset",
        "add a ramp_down over the same temperature range as the ramp_up (then a hold)",
    )


DEFINITION = Effect(
    identifier="hysteresis",
    compensable=True,
    excludes=("hysteresis_offset",),
    params=(
        Param("amp_mg", unit="mg", plausible=(0.02, 2.0)),
        Param("width_c", "positive", unit="degC", plausible=(2.0, 30.0)),
    ),
    summary="amp * (T_pm - P) / (width_c / 2), P the play operator of T_pm; bias_poly reads P",
    contribution=branch_contribution,
    bias_temperature=lambda T_pm, p, start: play_operator(T_pm, p["width_c"], start),
    finder=Finder(
        search="profile",
        nonlinear=(("width_c", True),),
        bounds=lambda data: ((0.5, 40.0),),
        grid_points=16,
        columns=_columns,
        identifiability=reversal_identifiability,
        advice=(
            "heating and cooling branches differ: a single polynomial splits the difference; calibrate on both "
            "branches and track the branch (the offset persists in holds)"
        ),
        confounders=("thermal_lag", "temp_rate", "hysteresis_offset"),
    ),
    scenario=Scenario(
        draw=lambda rng, duration, sign: {
            "amp_mg": sign * float(rng.uniform(0.05, 0.2)),
            "width_c": float(rng.uniform(2.0, 6.0)),
        },
        checked=("amp_mg", "width_c"),
        needs_reversal=True,
    ),
)
