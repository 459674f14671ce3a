"""The physics compensator sample by sample, exactly as firmware runs it (float64 reference).

One step per thermometer sample ``T`` (degC), every ``dt_s`` seconds::

    T      = clip(T, T_min, T_max)                       valid range: the training range's ends
    T_pm   = T, then what the temperature-chain effects make of it (a lag: a low-pass)
    T_b    = T_pm, or what a branch effect switches the polynomial to (the play output)
    drift  = the branch effects' terms + poly(T_b) + the additive effects' terms

Each effect's part is its streamed form (``trainer/physics/catalogue/<effect>_stream.py``, listed in
:mod:`trainer.physics.catalogue.streamed`); this module runs them in step order and adds the bias
polynomial. The low-passes are the simulator's exact first-order-hold discretisation
(:func:`trainer.physics.thermal.lowpass_coefficients`), so the stream reproduces the batch formula
(:func:`trainer.physics.effects.drift`) to rounding.

Power-on: every state word (filters, the play operator) starts at the first clipped temperature:
every filter in equilibrium (no lag, no rate, no creep) and the play operator half-way between the
branches. Until the temperature has moved by ``w/2`` in one direction a branch term is therefore
off by at most ``|amp|`` (half the gap between the branches). A model with a play start
(``play_start_c``, the temperature the sensor came from before power-on) starts the play operator
there instead, clamped into ``T_0 +- w/2`` by its first step: a sensor brought to ``T_0`` from room
temperature starts on the branch that journey left it on. A firmware that saves
:class:`StreamState` at power-down and restores it at power-up keeps the branch; the filters are
then right if the board was off for much less than their time constants (else start fresh).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Self

import numpy as np

from trainer.physics.catalogue import BACKBONE
from trainer.physics.catalogue.bias_poly import polynomial
from trainer.physics.catalogue.streamed import (
    STREAMED,
    instance_suffixes,
    instances_in_step_order,
    play_words,
)
from trainer.physics.catalogue.streaming import BRANCH, CHAIN, Sample, StreamedEffect
from trainer.physics.effects import EffectConfig, check_instances


def play_start_within(play_start_c: float | None, temp_range_c: tuple[float, float]) -> float | None:
    """The play operator's start clipped to the valid range, as every temperature the model reads."""
    return None if play_start_c is None else min(max(play_start_c, temp_range_c[0]), temp_range_c[1])


@dataclass(frozen=True)
class PhysicsModel:
    """Plain parameters of one fitted compensator (catalogue units): the bias polynomial, the
    training range and the streamed effects, in step order (an effect may have several instances:
    :func:`~trainer.physics.catalogue.streamed.instance_suffixes` names their state words)."""

    c_mg: tuple[float, float, float, float]  # bias_poly c0..c3 about T_REF_C
    temp_range_c: tuple[float, float]
    terms: tuple[EffectConfig, ...] = ()
    play_start_c: float | None = None  # where the play operator starts (clipped to the range); None: T_0

    @classmethod
    def from_effects(
        cls,
        effects: tuple[EffectConfig, ...],
        temp_range_c: tuple[float, float],
        play_start_c: float | None = None,
    ) -> Self:
        check_instances(e.identifier for e in effects)
        poly = next((e.params for e in effects if e.identifier == BACKBONE), {})
        order = instances_in_step_order([e.identifier for e in effects])
        terms = tuple(EffectConfig(effects[i].identifier, dict(effects[i].params)) for i in order)
        for term in terms:
            check = STREAMED[term.identifier].check
            if check is not None:
                check(term.params)
        return cls(
            c_mg=tuple(
                float(poly.get(k, 0.0)) for k in ("c0_mg", "c1_mg_per_c", "c2_mg_per_c2", "c3_mg_per_c3")
            ),  # type: ignore[arg-type]
            temp_range_c=temp_range_c,
            terms=terms,
            play_start_c=play_start_within(play_start_c, temp_range_c),
        )

    def static_drift_mg(self, temp_c: float) -> float:
        """The drift held long at ``temp_c`` (every filter settled, mid-branch, warm-up over)."""
        lo, hi = self.temp_range_c
        return float(polynomial(np.asarray(min(max(temp_c, lo), hi)), *self.c_mg))


@dataclass
class StreamState:
    """Everything the stream remembers between samples: what firmware saves across a power cycle
    (``values``: each streamed effect's state words, in degC)."""

    started: bool = False
    temp_prev_c: float = 0.0
    time_s: float = 0.0
    values: dict[str, float] = field(default_factory=dict)


class PhysicsStream:
    """Sample-by-sample drift of a :class:`PhysicsModel` at a fixed sample period ``dt_s`` (the
    terms that need the time since power-on only ``with_power_on_time``)."""

    def __init__(self, model: PhysicsModel, dt_s: float, *, with_power_on_time: bool = True) -> None:
        self.model = model
        self.dt_s = dt_s
        suffixes = instance_suffixes([e.identifier for e in model.terms])
        parts = [
            (STREAMED[e.identifier], e.params, suffix)
            for e, suffix in zip(model.terms, suffixes, strict=True)
        ]
        self.parts: list[tuple[StreamedEffect, Mapping[str, float], tuple[float, ...], str]] = [
            (effect, params, effect.prepare(params, dt_s), suffix)
            for effect, params, suffix in parts
            if with_power_on_time or not effect.needs_power_on_time
        ]
        self.state = StreamState()

    def restore(self, state: StreamState) -> None:
        """Continue from a saved state (see the module docstring for when that is right)."""
        self.state = StreamState(state.started, state.temp_prev_c, state.time_s, dict(state.values))

    def step(self, temp_c: float) -> float:
        m, s = self.model, self.state
        lo, hi = m.temp_range_c
        T = min(max(temp_c, lo), hi)
        if not s.started:
            s.started, s.temp_prev_c = True, T
            play, starts_at_play = (T if m.play_start_c is None else m.play_start_c), play_words()
            s.values = {
                word + suffix: play if word in starts_at_play else T
                for effect, _, _, suffix in self.parts
                for word in effect.state
            }
        sample = Sample(T, s.temp_prev_c, T, T, s.time_s)
        drift = 0.0
        for effect, params, constants, suffix in self.parts:
            if effect.phase in (CHAIN, BRANCH):
                drift += _step(effect, params, constants, s.values, sample, suffix)
        drift += float(polynomial(np.asarray(sample.T_b), *m.c_mg))
        for effect, params, constants, suffix in self.parts:
            if effect.phase not in (CHAIN, BRANCH):
                drift += _step(effect, params, constants, s.values, sample, suffix)
        s.temp_prev_c = T
        s.time_s += self.dt_s
        return drift


def _step(
    effect: StreamedEffect,
    params: Mapping[str, float],
    constants: tuple[float, ...],
    values: dict[str, float],
    sample: Sample,
    suffix: str,
) -> float:
    """One term's step on its own state words (an effect's later instance keeps them suffixed)."""
    if not suffix:
        return effect.step(params, constants, values, sample)
    own = {word: values[word + suffix] for word in effect.state}
    drift = effect.step(params, constants, own, sample)
    values.update({word + suffix: value for word, value in own.items()})
    return drift
