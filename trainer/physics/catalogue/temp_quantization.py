"""``temp_quantization``: the thermometer column is rounded to multiples of ``lsb_c`` (a staircase)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue.base import (
    BlockDesign,
    Effect,
    Finder,
    FinderData,
    FinderProfile,
    FinderTerm,
    Identifiability,
    Param,
    Scenario,
    StartContext,
    StartingTerm,
)


def quantize(temp_c: np.ndarray, lsb_c: float) -> np.ndarray:
    """Round to the nearest multiple of ``lsb_c`` (ties to even)."""
    return lsb_c * np.round(np.asarray(temp_c, dtype=np.float64) / lsb_c)


def _columns(term: FinderTerm, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    # In a quantised hold the true temperature is only known within +-LSB/2: an unknown
    # offset per plateau (the polynomial's slope times that temperature error).
    t = d.data.t
    out = []
    for k, (p0, p1) in enumerate(d.data.plateaus):
        inside = ((t >= p0) & (t < p1)).astype(np.float64)
        if inside.sum() >= 2:
            out.append((f"plateau{k}", inside))
    return out


def _from_config(p: Mapping[str, float], ctx: StartContext) -> StartingTerm:
    if ctx.lattice_lsb_c is None:
        note = "temp_quantization is listed but the thermometer column is not on a lattice"
        return StartingTerm((p["lsb_c"],), fixed=True, note=note)
    return StartingTerm((ctx.lattice_lsb_c,), fixed=True)


def _identifiability(p: FinderProfile) -> Identifiability:
    if p.lattice_lsb_c is not None:
        return Identifiability(
            True, f"the thermometer column lies on a {p.lattice_lsb_c:g} degC lattice (a staircase)"
        )
    return Identifiability(
        False, "the thermometer column is not quantised (no lattice of equal steps)", "", weak=False
    )


def _unused_note(data: FinderData) -> str:
    if data.lattice_lsb_c is None:
        return ""
    return (
        f"the thermometer column is quantised ({data.lattice_lsb_c:g} degC) but modelling the staircase "
        "does not improve the fit"
    )


DEFINITION = Effect(
    identifier="temp_quantization",
    params=(Param("lsb_c", "positive", unit="degC", plausible=(0.0625, 1.0)),),
    summary="the thermometer column is rounded to multiples of lsb_c (the model sees a staircase)",
    thermometer=lambda temp_c, p: quantize(temp_c, p["lsb_c"]),
    finder=Finder(
        search="lattice",  # the LSB is read off the thermometer column's lattice, not searched
        bic_nonlinear=1,  # ... but it is estimated
        dequantize=True,
        absent_when_unidentifiable=True,  # no lattice: the thermometer is not quantised
        unused_note=_unused_note,
        columns=_columns,
        to_params=lambda term, lin: {"lsb_c": term.nl[0]},
        from_config=_from_config,
        identifiability=_identifiability,
        advice=(
            "the temperature reading comes in coarse steps: a polynomial on the staircase leaves a sawtooth; "
            "interpolate or low-pass the temperature before the compensation"
        ),
        confounders=("thermal_lag",),
    ),
    scenario=Scenario(
        draw=lambda rng, duration, sign: {"lsb_c": float(rng.choice([0.5, 0.625]))},
        checked=("lsb_c",),
        min_slope_mg_per_c=0.2,  # a staircase matters only on a steep enough bias curve
        fine_thermometer=True,
    ),
)
