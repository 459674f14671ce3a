"""``hysteresis`` streamed: the play operator of ``T_pm`` and its branch offset; the polynomial
reads the play output. :func:`branch` is shared with ``hysteresis_offset`` (the same C)."""

from __future__ import annotations

from fractions import Fraction

from trainer.physics.catalogue.hysteresis import DEFINITION
from trainer.physics.catalogue.streaming import (
    BRANCH,
    FixedPoint,
    GoldenStep,
    IntSample,
    IntTerm,
    Params,
    Sample,
    StateWord,
    StreamedEffect,
)

WORD = "play"


def _margin(p: Params) -> tuple[Fraction, str]:
    """Half the play width in mdegC (0 when the width is not positive: the quantiser refuses it)."""
    width = p["width_c"]
    return (Fraction(width) * 500 if width > 0 else Fraction(0)), f"play width {width!r} degC"


def branch(identifier: str, *, reads_play: bool) -> StreamedEffect:
    """The play operator of ``T_pm`` (width ``width_c``) and ``amp (T_pm - P) / (width / 2)``."""

    def step(p: Params, _: tuple[float, ...], v: dict[str, float], s: Sample) -> float:
        half = p["width_c"] / 2.0
        v[WORD] = min(max(v[WORD], s.T_pm - half), s.T_pm + half)
        if reads_play:
            s.T_b = v[WORD]
        return p["amp_mg"] * (s.T_pm - v[WORD]) / half

    def golden(q: IntTerm) -> GoldenStep:
        assert q.margin_q is not None and q.gain is not None
        half, gain = q.margin_q, q.gain.q

        def step(v: dict[str, int], s: IntSample) -> int:
            t_pm, p = s.t_pm, v[WORD]
            if p < t_pm - half:  # tdcp_play: P within T_pm +- w/2
                p = t_pm - half
            elif p > t_pm + half:
                p = t_pm + half
            v[WORD] = p
            if reads_play:
                s.t_b = p
            return (t_pm - p) * gain

        return step

    return StreamedEffect(
        identifier=identifier,
        phase=BRANCH,
        state=(WORD,),
        prepare=lambda p, dt_s: (),
        step=step,
        fixed=FixedPoint(
            name="branch",
            state=(
                StateWord(
                    WORD,
                    False,
                    "play operator output P (the hysteresis branch)",
                    imu_doc="play operator output (the hysteresis branch), Q(tf) mdegC",
                ),
            ),
            golden=golden,
            before_poly=(
                "    /* play operator of half width ${margin_text} */\n"
                f"    state->{WORD} = tdcp_play(state->{WORD}, t_pm, ${{margin}});\n"
            ),
            after_poly=f"    acc += (int64_t)(t_pm - state->{WORD}) * ${{q}};\n",
            gain_mg_per_c=lambda p: p["amp_mg"] / (p["width_c"] / 2.0),
            gain_name="branch",
            difference="margin",
            difference_text="(T_pm - P)",
            margin=_margin,
            margin_field="half_width",
            margin_doc="play operator, Q(tf) mdegC",
            proof_mass_weight=2.0,  # T_pm - P moves by at most twice an error of T_pm
            poly_reads=WORD if reads_play else None,
        ),
    )


STREAMED = branch(DEFINITION.identifier, reads_play=True)
