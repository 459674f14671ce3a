"""``thermal_lag`` streamed: the proof-mass temperature ``T_pm`` as a low-pass of the thermometer."""

from __future__ import annotations

from trainer.physics.catalogue.streaming import (
    CHAIN,
    HI_BITS,
    FixedPoint,
    GoldenStep,
    IntSample,
    IntTerm,
    Params,
    Sample,
    StateWord,
    StreamedEffect,
    lowpass_call,
    lowpass_constants,
    lowpass_int,
    lowpass_step,
)
from trainer.physics.catalogue.thermal_lag import DEFINITION

WORD = "proof_mass"


def _step(p: Params, lp: tuple[float, ...], v: dict[str, float], s: Sample) -> float:
    v[WORD] = s.T_pm = s.T_b = lowpass_step(lp, v[WORD], s)
    return 0.0


def _golden(q: IntTerm) -> GoldenStep:
    assert q.filter is not None
    lowpass = lowpass_int(q.filter)

    def step(v: dict[str, int], s: IntSample) -> int:
        v[WORD] = y = lowpass(v[WORD], s)
        s.t_pm = s.t_b = y >> HI_BITS
        return 0

    return step


STREAMED = StreamedEffect(
    identifier=DEFINITION.identifier,
    phase=CHAIN,
    state=(WORD,),
    prepare=lambda p, dt_s: lowpass_constants(p["tau_s"], dt_s),
    step=_step,
    fixed=FixedPoint(
        name="lag",
        state=(StateWord(WORD, True, f"{DEFINITION.identifier}: proof-mass temperature T_pm"),),
        golden=_golden,
        before_poly=lowpass_call(WORD) + f"    t_pm = tdcp_hi(state->{WORD});\n",
        tau_s=lambda p: p["tau_s"],
        filter_name=DEFINITION.identifier,
        filter_doc=f"{DEFINITION.identifier}: proof-mass temperature",
    ),
)
