"""The physics compensator sample by sample, exactly as firmware runs it (float64 reference).

One step per thermometer sample ``T`` (degC), every ``dt_s`` seconds::

    T      = clip(T, T_min, T_max)                       valid range: the training range's ends
    T_pm   = a_l T_pm + b0_l T + b1_l T_prev             thermal_lag: first-order low-pass, tau_lag
    P      = min(max(P, T_pm - w/2), T_pm + w/2)         hysteresis(_offset): the play operator
    T_b    = P (hysteresis) or T_pm                      what the bias polynomial reads
    R      = a_r R + b0_r T + b1_r T_prev                temp_rate: rate filter (tau_rate >= 30 s)
    C      = a_c C + b0_c T + b1_c T_prev                stress_relaxation: creep filter, tau_creep
    drift  = poly(T_b) + amp (T_pm - P) / (w/2) + k 60 (T - R) / tau_rate + gain (T - C)
             + amp_w exp(-t / tau_w)                     warmup: t since power-on (optional)

The low-passes are the simulator's exact first-order-hold discretisation
(:func:`trainer.physics.thermal.lowpass_coefficients`), so the stream reproduces the batch formula
(:func:`trainer.physics.effects.drift`) to rounding. ``60 (T - R) / tau_rate`` is the temperature
rate low-passed over ``tau_rate`` in degC/min, computed without a numerical derivative (which a
quantised thermometer would turn into spikes); it lags the true rate by about ``tau_rate``.

Power-on: every filter starts in equilibrium at the first temperature (no lag, no rate, no creep)
and the play operator at the first ``T_pm``, i.e. half-way between the branches. Until the
temperature has moved by ``w/2`` in one direction the hysteresis term is therefore off by at most
``|amp|`` (half the gap between the branches). A firmware that saves :class:`StreamState` at
power-down and restores it at power-up keeps the branch; the filters are then right if the board
was off for much less than their time constants (else start fresh).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Self

import numpy as np

from trainer.greybox.terms import CREEP, HYSTERESIS, HYSTERESIS_OFFSET, LAG, RATE, WARMUP
from trainer.physics.catalogue import BACKBONE
from trainer.physics.catalogue.bias_poly import polynomial
from trainer.physics.effects import EffectConfig
from trainer.physics.thermal import lowpass_coefficients


@dataclass(frozen=True)
class PhysicsModel:
    """Plain parameters of one fitted compensator (catalogue units; 0 or None: term absent)."""

    c_mg: tuple[float, float, float, float]  # bias_poly c0..c3 about T_REF_C
    temp_range_c: tuple[float, float]
    lag_tau_s: float | None = None
    play_width_c: float | None = None
    branch_amp_mg: float = 0.0
    poly_reads_play: bool = False  # catalogue hysteresis (True) or hysteresis_offset (False)
    rate_k_mg_per_c_per_min: float = 0.0
    rate_tau_s: float | None = None
    creep_gain_mg_per_c: float = 0.0
    creep_tau_s: float | None = None
    warmup_amp_mg: float = 0.0
    warmup_tau_s: float | None = None

    @classmethod
    def from_effects(cls, effects: tuple[EffectConfig, ...], temp_range_c: tuple[float, float]) -> Self:
        p = {e.identifier: e.params for e in effects}
        poly = p.get(BACKBONE, {})
        branch = p.get(HYSTERESIS) or p.get(HYSTERESIS_OFFSET)
        rate = p.get(RATE)
        if rate is not None and not rate.get("tau_s", 0.0) > 0:
            raise ValueError("the streaming form needs a rate filter: temp_rate tau_s > 0")
        return cls(
            c_mg=tuple(
                float(poly.get(k, 0.0)) for k in ("c0_mg", "c1_mg_per_c", "c2_mg_per_c2", "c3_mg_per_c3")
            ),  # type: ignore[arg-type]
            temp_range_c=temp_range_c,
            lag_tau_s=p[LAG]["tau_s"] if LAG in p else None,
            play_width_c=None if branch is None else branch["width_c"],
            branch_amp_mg=0.0 if branch is None else branch["amp_mg"],
            poly_reads_play=HYSTERESIS in p,
            rate_k_mg_per_c_per_min=0.0 if rate is None else rate["k_mg_per_c_per_min"],
            rate_tau_s=None if rate is None else rate["tau_s"],
            creep_gain_mg_per_c=p[CREEP]["gain_mg_per_c"] if CREEP in p else 0.0,
            creep_tau_s=p[CREEP]["tau_s"] if CREEP in p else None,
            warmup_amp_mg=p[WARMUP]["amp_mg"] if WARMUP in p else 0.0,
            warmup_tau_s=p[WARMUP]["tau_s"] if WARMUP in p else None,
        )

    def static_drift_mg(self, temp_c: float) -> float:
        """The drift held long at ``temp_c`` (every filter settled, mid-branch, warm-up over)."""
        lo, hi = self.temp_range_c
        return float(polynomial(np.asarray(min(max(temp_c, lo), hi)), *self.c_mg))


@dataclass
class StreamState:
    """Everything the stream remembers between samples: what firmware saves across a power cycle."""

    started: bool = False
    temp_prev_c: float = 0.0
    proof_mass_c: float = 0.0
    play_c: float = 0.0
    rate_lp_c: float = 0.0
    creep_lp_c: float = 0.0
    time_s: float = 0.0


def _coefficients(tau_s: float | None, dt_s: float) -> tuple[float, float, float]:
    if tau_s is None:
        return (0.0, 1.0, 0.0)  # y = x
    (b0, b1), (_, minus_a) = lowpass_coefficients(tau_s, dt_s)
    return (-float(minus_a), float(b0), float(b1))


class PhysicsStream:
    """Sample-by-sample drift of a :class:`PhysicsModel` at a fixed sample period ``dt_s``."""

    def __init__(self, model: PhysicsModel, dt_s: float, *, with_warmup: bool = True) -> None:
        self.model = model
        self.dt_s = dt_s
        self.with_warmup = with_warmup and model.warmup_tau_s is not None
        self.lag = _coefficients(model.lag_tau_s, dt_s)
        self.rate = _coefficients(model.rate_tau_s, dt_s)
        self.creep = _coefficients(model.creep_tau_s, dt_s)
        self.state = StreamState()

    def restore(self, state: StreamState) -> None:
        """Continue from a saved state (see the module docstring for when that is right)."""
        self.state = StreamState(**vars(state))

    def step(self, temp_c: float) -> float:
        m, s = self.model, self.state
        lo, hi = m.temp_range_c
        T = min(max(temp_c, lo), hi)
        if not s.started:
            s.started, s.temp_prev_c = True, T
            s.proof_mass_c = s.play_c = s.rate_lp_c = s.creep_lp_c = T
        a, b0, b1 = self.lag
        s.proof_mass_c = a * s.proof_mass_c + b0 * T + b1 * s.temp_prev_c if m.lag_tau_s else T
        drift = 0.0
        T_b = s.proof_mass_c
        if m.play_width_c is not None:
            half = m.play_width_c / 2.0
            s.play_c = min(max(s.play_c, s.proof_mass_c - half), s.proof_mass_c + half)
            drift += m.branch_amp_mg * (s.proof_mass_c - s.play_c) / half
            if m.poly_reads_play:
                T_b = s.play_c
        drift += float(polynomial(np.asarray(T_b), *m.c_mg))
        if m.rate_tau_s is not None:
            a, b0, b1 = self.rate
            s.rate_lp_c = a * s.rate_lp_c + b0 * T + b1 * s.temp_prev_c
            drift += m.rate_k_mg_per_c_per_min * 60.0 * (T - s.rate_lp_c) / m.rate_tau_s
        if m.creep_tau_s is not None:
            a, b0, b1 = self.creep
            s.creep_lp_c = a * s.creep_lp_c + b0 * T + b1 * s.temp_prev_c
            drift += m.creep_gain_mg_per_c * (T - s.creep_lp_c)
        if self.with_warmup and m.warmup_tau_s is not None:
            drift += m.warmup_amp_mg * math.exp(-s.time_s / m.warmup_tau_s)
        s.temp_prev_c = T
        s.time_s += self.dt_s
        return drift
