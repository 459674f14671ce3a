"""``temp_rate`` streamed: ``k 60 (T - R) / tau_s`` with R a low-pass of T over ``tau_s``, the
temperature rate low-passed over ``tau_s`` in degC/min without a numerical derivative (which a
quantised thermometer would turn into spikes); it lags the true rate by about ``tau_s``."""

from __future__ import annotations

from trainer.physics.catalogue.streaming import (
    ADDITIVE,
    Params,
    Sample,
    StreamedEffect,
    filtered_difference,
    lowpass_constants,
    lowpass_step,
)
from trainer.physics.catalogue.temp_rate import DEFINITION

WORD = "rate_lp"
# The shortest rate filter (s): the derivative of a thermometer with 0.01-0.04 degC noise and a
# 0.0625 degC LSB, low-passed over 30 s, is good to about 0.05 degC/min; it lags the true rate by
# this much (a first-order filter's group delay at low frequency is its time constant).
RATE_TAU_MIN_S = 30.0


def _gain_mg_per_c(p: Params) -> float:
    return p["k_mg_per_c_per_min"] * 60.0 / p["tau_s"]


def _step(p: Params, lp: tuple[float, ...], v: dict[str, float], s: Sample) -> float:
    v[WORD] = lowpass_step(lp, v[WORD], s)
    return p["k_mg_per_c_per_min"] * 60.0 * (s.T - v[WORD]) / p["tau_s"]


def _check(p: Params) -> None:
    if not p.get("tau_s", 0.0) > 0:
        raise ValueError(f"the streaming form needs a rate filter: {DEFINITION.identifier} tau_s > 0")


STREAMED = StreamedEffect(
    identifier=DEFINITION.identifier,
    phase=ADDITIVE,
    state=(WORD,),
    prepare=lambda p, dt_s: lowpass_constants(p["tau_s"], dt_s),
    step=_step,
    check=_check,
    min_filter_s=RATE_TAU_MIN_S,
    fixed=filtered_difference(
        WORD,
        name="rate",
        identifier=DEFINITION.identifier,
        doc="the rate filter",
        tau_s=lambda p: p["tau_s"],
        gain_mg_per_c=_gain_mg_per_c,
        letter="R",
    ),
)
