"""``scale_factor_tc``: the scale factor drifts with temperature, ``g_in * 1e-6 * sf * (T_pm - T_ref)``."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from trainer.data.channels import DEFAULT_UNIT, SECOND_INPUT
from trainer.physics.catalogue.base import (
    T_REF_C,
    BlockDesign,
    Effect,
    Finder,
    FinderData,
    FinderProfile,
    FinderTerm,
    Identifiability,
    Param,
    Signals,
    StartContext,
    StartingTerm,
)


def scale_error(g_in_mg: np.ndarray | float, T_pm: np.ndarray, sf_ppm_per_c: float) -> np.ndarray:
    return np.asarray(g_in_mg, dtype=np.float64) * 1e-6 * sf_ppm_per_c * (T_pm - T_REF_C)


def _contribution(p: Mapping[str, float], s: Signals) -> np.ndarray:
    g = p.get("g_in_mg", s.g_in_mg)
    if g is None:
        raise ValueError("scale_factor_tc needs g_in_mg (parameter or argument)")
    return scale_error(g, s.T_pm, p["sf_ppm_per_c"])


def _columns(term: FinderTerm, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    g = d.data.known_input_block
    if g is None:  # a zero input: nothing to fit (the configured value is kept)
        return []
    return [("sf_ppm_per_c", g * 1e-6 * (d.T_pm - T_REF_C))]


def _full_rate(lin: Mapping[str, float], data: FinderData, T_pm: np.ndarray) -> np.ndarray | None:
    """The fitted tempco on the known input (drift() runs at a zero input)."""
    if data.known_input_block is None or "sf_ppm_per_c" not in lin:
        return None
    g = np.interp(data.full_t, data.t, data.known_input_block)
    return scale_error(g, T_pm, lin["sf_ppm_per_c"])


def _from_config(p: Mapping[str, float], ctx: StartContext) -> StartingTerm:
    note = (
        ""
        if ctx.input_varies
        else "scale_factor_tc is kept at the configured value: with a constant input it equals "
        "bias_poly's linear term and cannot be calibrated"
    )
    return StartingTerm((p["sf_ppm_per_c"],), fixed=True, note=note)


def _identifiability(p: FinderProfile) -> Identifiability:
    if p.known_input_varies:
        return Identifiability(True, "the known true input changes (a second orientation)")
    return Identifiability(
        False,
        "a single static orientation: the scale-factor tempco times a constant input equals the "
        "polynomial's linear term (a fixture tilt is a constant c0 the same way)",
        # written for milli-g (relabel_units names a gyroscope's or barometer's own)
        f"a known second input at several temperatures: {SECOND_INPUT[DEFAULT_UNIT]}",
    )


DEFINITION = Effect(
    identifier="scale_factor_tc",
    params=(
        # plausible 10 to 300 ppm/degC; not flagged: the finder fits it only when the input varies
        Param("sf_ppm_per_c", unit="ppm/degC", plausible=(10.0, 300.0), flagged=False),
        Param("g_in_mg", optional=True, unit="mg"),
    ),
    summary="g_in * 1e-6 * sf * (T_pm - T_ref); g_in_mg, when given, is the constant true input",
    contribution=_contribution,
    input_param="g_in_mg",
    finder=Finder(
        search="linear",
        columns=_columns,
        # fitted only when the known input varies; otherwise the user's value is kept
        to_params=lambda term, lin: {"sf_ppm_per_c": lin.get("sf_ppm_per_c", term.nl[0] if term.nl else 0.0)},
        full_rate=_full_rate,
        from_config=_from_config,
        identifiability=_identifiability,
        advice="the scale factor drifts with temperature: a compensation at one orientation is off at another",
    ),
)
