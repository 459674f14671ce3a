"""``bias_step``: a bias step (shock, mode hop), ``step * H(t - t_s)`` with ``H(0) = 1`` (repeatable)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue.base import (
    BlockDesign,
    Effect,
    Finder,
    FinderData,
    FinderTerm,
    Identifiability,
    Param,
    Region,
    Scenario,
    WhereContext,
)

STEP_WINDOW_BLOCKS = 10  # blocks either side of a step whose residual is tested
RESOLUTION_BLOCKS = 2.0  # step times closer than this many blocks are one step


def step(t: np.ndarray, t_s: float, step_mg: float) -> np.ndarray:
    return np.where(t >= t_s, step_mg, 0.0)


def _columns(term: FinderTerm, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    B = d.data.block_s  # the block mean of a step inside the block is the fraction after it
    return [("step_mg", np.clip((d.data.t + 0.5 * B - term.nl[0]) / B, 0.0, 1.0))]


def _same_instance(a: FinderTerm, b: FinderTerm, data: FinderData) -> bool:
    """Two step times within ``RESOLUTION_BLOCKS`` blocks: the block means cannot tell them apart."""
    return bool(abs(a.nl[0] - b.nl[0]) <= RESOLUTION_BLOCKS * data.block_s)


def _where(p: Mapping[str, float], ctx: WhereContext) -> list[Region]:
    """The blocks around the step, with the residual's z on either side of it."""
    data = ctx.data
    j = int(np.clip(np.searchsorted(data.starts, p["t_s"]), 1, data.n - 1))
    a, b = max(0, j - 1), min(data.n, j + 1)
    before_z = ctx.window_z(max(0, j - STEP_WINDOW_BLOCKS), j)
    after_z = ctx.window_z(j, min(data.n, j + STEP_WINDOW_BLOCKS))
    sig = {"z_before": before_z, "z_after": after_z}
    return [ctx.region(a, b, sig, "change_point", f"step of {p['step_mg']:.4g} mg at {p['t_s']:.1f} s")]


DEFINITION = Effect(
    identifier="bias_step",
    params=(
        Param("t_s", "nonnegative", unit="s"),
        Param("step_mg", unit="mg", plausible=(0.02, 5.0)),
    ),
    summary="step * H(t - t_s) (shock, mode hop)",
    contribution=lambda p, s: step(s.t, p["t_s"], p["step_mg"]),
    multi_instance=True,
    finder=Finder(
        search="step",
        nonlinear=(("t_s", False),),
        bounds=lambda data: ((data.starts[2], data.starts[-2]),),
        max_terms=8,  # a run can hold several events (shocks, mode hops) at distinct times (the bundled
        # run's gyro x holds four; at 5, two steps added to it left one of the four out unsaid)
        same_instance=_same_instance,
        # a step time found by an exhaustive scan counts twice (modified BIC for change points,
        # Zhang & Siegmund 2007): its look-elsewhere effect is far larger than a time constant's
        bic_nonlinear=2,
        event_time=True,
        columns=_columns,
        where=_where,
        identifiability=lambda p: Identifiability(True, "a step shows anywhere in the run"),
        advice="a bias step (shock, mode hop, reset): the compensation is offset after it",
        confounders=("warmup",),
        separations={
            "warmup": (
                "a step is instantaneous and permanent; a warm-up decays exponentially from power-on (a longer "
                "soak after power-on, or a higher sample rate at the start, shows the shape)"
            )
        },
    ),
    scenario=Scenario(
        draw=lambda rng, duration, sign: {
            "t_s": float(rng.uniform(0.25, 0.8) * duration),
            "step_mg": sign * float(rng.uniform(0.15, 0.4)),
        },
        checked=("step_mg",),
    ),
)
