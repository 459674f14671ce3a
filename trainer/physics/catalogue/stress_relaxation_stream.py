"""``stress_relaxation`` streamed: ``gain (T - C)`` with C a low-pass of T over ``tau_s`` (package creep)."""

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
from trainer.physics.catalogue.stress_relaxation import DEFINITION

WORD = "creep_lp"


def _step(p: Params, lp: tuple[float, ...], v: dict[str, float], s: Sample) -> float:
    v[WORD] = lowpass_step(lp, v[WORD], s)
    return p["gain_mg_per_c"] * (s.T - v[WORD])


STREAMED = StreamedEffect(
    identifier=DEFINITION.identifier,
    phase=ADDITIVE,
    state=(WORD,),
    prepare=lambda p, dt_s: lowpass_constants(p["tau_s"], dt_s),
    step=_step,
    fixed=filtered_difference(
        WORD,
        name="creep",
        identifier=DEFINITION.identifier,
        doc="the creep filter",
        tau_s=lambda p: p["tau_s"],
        gain_mg_per_c=lambda p: p["gain_mg_per_c"],
        letter="C",
    ),
)
