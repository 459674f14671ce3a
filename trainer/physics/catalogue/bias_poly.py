"""``bias_poly``: the static bias-temperature curve, the backbone of every model."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue.base import T_REF_C, BlockDesign, Effect, Finder, FinderTerm, Param, Signals

POLY_SCALE_C = 50.0  # finder columns ((T - 25) / 50)^k keep the GLS well conditioned


def polynomial(T_b: np.ndarray, c0: float, c1: float, c2: float, c3: float) -> np.ndarray:
    """``sum_k c_k (T_b - T_ref)^k`` (Horner)."""
    d = T_b - T_REF_C
    return c0 + d * (c1 + d * (c2 + d * c3))


def absorbed_fraction(T: np.ndarray, signal: np.ndarray) -> float:
    """Share of ``signal``'s sum of squares (about its mean) that a cubic in ``T`` absorbs by least
    squares: near 1, the signal is a function of temperature on this profile and cannot be told
    from the bias polynomial."""
    u = (np.asarray(T, dtype=np.float64) - T_REF_C) / POLY_SCALE_C
    X = np.column_stack([u**k for k in range(4)])
    beta, *_ = np.linalg.lstsq(X, signal, rcond=None)
    total = float(np.sum((signal - np.mean(signal)) ** 2))
    left = float(np.sum((signal - X @ beta) ** 2))
    return 1.0 - left / total if total > 0 else 1.0


def _contribution(p: Mapping[str, float], s: Signals) -> np.ndarray:
    return polynomial(s.T_b, p["c0_mg"], p["c1_mg_per_c"], p["c2_mg_per_c2"], p["c3_mg_per_c3"])


def _columns(term: FinderTerm, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    u = (d.T_b - T_REF_C) / POLY_SCALE_C
    return [(f"c{k}", u**k) for k in range(4)]


def _to_params(term: FinderTerm, lin: Mapping[str, float]) -> dict[str, float]:
    return {
        "c0_mg": lin["c0"],
        "c1_mg_per_c": lin["c1"] / POLY_SCALE_C,
        "c2_mg_per_c2": lin["c2"] / POLY_SCALE_C**2,
        "c3_mg_per_c3": lin["c3"] / POLY_SCALE_C**3,
    }


DEFINITION = Effect(
    identifier="bias_poly",
    params=(
        Param("c0_mg", default=0.0, unit="mg"),
        Param("c1_mg_per_c", default=0.0, unit="mg/degC"),
        Param("c2_mg_per_c2", default=0.0, unit="mg/degC^2"),
        Param("c3_mg_per_c3", default=0.0, unit="mg/degC^3"),
    ),
    summary="sum_k c_k (T_b - T_ref)^k; catalogue plausible drift 1 to 50 mg over -40..80 degC",
    contribution=_contribution,
    # Always in the finder's model (it always re-fits the polynomial jointly with the other terms:
    # what it absorbs of a missing effect is no evidence), so no search, advice or rule.
    finder=Finder(columns=_columns, to_params=_to_params, backbone=True),
)
