"""Generated recordings with concealed effects: the finder's test bench (tests and bench/ use it).

A scenario draws, from one seed, a chamber protocol (soak, ramps at two different rates, holds,
optionally a reversal), a sample rate, noise levels, a bias polynomial, and the concealed
effect(s) with catalogue parameters. The concealed effect's contribution is kept at or below
the per-sample noise (the white noise is raised when a draw would be visible sample by sample),
and :func:`concealment` measures how much of it a cubic polynomial in temperature absorbs.
The user's simulation handed to the finder is the same configuration without the concealed
effects, so a correct finder names exactly them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from trainer.data.recording import Recording
from trainer.physics.catalogue import BACKBONE, DEFINITIONS, EFFECTS, NOISE, WHITE_NOISE
from trainer.physics.catalogue.base import Scenario as BenchSpec
from trainer.physics.catalogue.bias_poly import polynomial
from trainer.physics.config import (
    NoiseConfig,
    PhysicsConfig,
    ProtocolConfig,
    RecordingConfig,
    TemperatureConfig,
)
from trainer.physics.effects import EffectConfig
from trainer.physics.profiles import SegmentSpec
from trainer.physics.simulate import simulate

# What the bench can conceal (effects, then noise terms, in catalogue order) and which parameters
# each must recover (time constants and amplitudes), for tests and bench: from the definitions.
HIDDEN_EFFECTS: tuple[str, ...] = tuple(
    k for k, d in DEFINITIONS.items() if d.scenario is not None and d.scenario.draw is not None
)
CHECKED_PARAMS: dict[str, tuple[str, ...]] = {k: DEFINITIONS[k].scenario.checked for k in HIDDEN_EFFECTS}  # type: ignore[union-attr]


def _bench(identifier: str) -> BenchSpec:
    return DEFINITIONS[identifier].scenario or BenchSpec()


@dataclass(frozen=True)
class Scenario:
    name: str
    seed: int
    truth: PhysicsConfig  # what generated the recording
    sim: PhysicsConfig  # what the user believes: truth without the concealed effects
    hidden: tuple[EffectConfig, ...]  # the concealed effects (rate_random_walk as a noise term)

    def recording(self) -> Recording:
        return simulate(self.truth, self.seed)


def _protocol(rng: np.random.Generator, reversal: bool, long_holds: bool = False) -> ProtocolConfig:
    start = float(rng.uniform(-40.0, -15.0))
    top = float(rng.uniform(60.0, 85.0))
    r1 = float(rng.uniform(0.7, 2.0))
    r2 = r1 * float(rng.choice([0.5, 1.6]))
    segments = [SegmentSpec("soak", float(rng.uniform(1200.0, 2400.0)), start)]
    if rng.random() < 0.4:  # two ramp rates on the way up (an uneven heating rate)
        mid = start + (top - start) * float(rng.uniform(0.35, 0.65))
        segments.append(SegmentSpec("ramp_up", (mid - start) / r1 * 60.0, mid))
        segments.append(SegmentSpec("ramp_up", (top - mid) / r2 * 60.0, top))
        r_down = r1
    else:
        segments.append(SegmentSpec("ramp_up", (top - start) / r1 * 60.0, top))
        r_down = r2
    hold = (5400.0, 7200.0) if long_holds else (1800.0, 3600.0)  # creep needs a hold of >= 1.5 time constants
    segments.append(SegmentSpec("hold", float(rng.uniform(*hold)), top))
    if reversal:
        bottom = float(rng.uniform(10.0, 30.0))
        segments.append(SegmentSpec("ramp_down", (top - bottom) / r_down * 60.0, bottom))
        segments.append(SegmentSpec("hold", float(rng.uniform(1200.0, 2400.0)), bottom))
    return ProtocolConfig("custom", start, tuple(segments))


def _draw_effect(
    effect: str, rng: np.random.Generator, protocol: ProtocolConfig, slope: float
) -> EffectConfig | None:
    """A concealed instance of bias effect ``effect`` (``None`` for a noise term, drawn earlier)."""
    duration = sum(s.duration_s for s in protocol.segments)
    sign = float(rng.choice([-1.0, 1.0]))
    definition = EFFECTS.get(effect)
    if definition is None or definition.scenario is None or definition.scenario.draw is None:
        return None
    return EffectConfig(effect, definition.scenario.draw(rng, duration, sign))


def make_scenario(
    effects: Sequence[str], seed: int, *, rates: Sequence[float] = (2.0, 5.0, 10.0)
) -> Scenario:
    """A generated case with ``effects`` concealed (empty: a clean recording)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7919]))
    # Hysteresis needs a reversal and a random walk one that decouples time from temperature (else
    # the polynomial absorbs it); creep needs long holds: the tests use protocols that can show them.
    specs = [_bench(effect) for effect in effects]
    reversal = bool(rng.random() < 0.75) or any(spec.needs_reversal for spec in specs)
    protocol = _protocol(rng, reversal, long_holds=any(spec.long_holds for spec in specs))
    fs = float(rng.choice(list(rates)))
    slope = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.05, 0.25))
    min_slope = max((spec.min_slope_mg_per_c for spec in specs), default=0.0)
    if min_slope > 0:  # e.g. a staircase matters only on a steep enough bias curve
        slope = math.copysign(max(abs(slope), min_slope), slope)
    poly = EffectConfig(
        BACKBONE,
        {
            "c0_mg": float(rng.uniform(-1.0, 1.0)),
            "c1_mg_per_c": slope,
            "c2_mg_per_c2": float(rng.uniform(-1.5e-3, 1.5e-3)),
            "c3_mg_per_c3": float(rng.uniform(-8e-6, 8e-6)),
        },
    )
    # The user's noise model: every noise term with a bench level, in catalogue order (white noise,
    # bias instability, random walk); a concealed noise term is drawn larger and left out of it.
    known = {k: d.scenario.known(rng) for k, d in NOISE.items() if d.scenario and d.scenario.known}
    hidden: list[EffectConfig] = []
    for k in known:
        draw = _bench(k).draw
        if k in effects and draw is not None:
            hidden.append(EffectConfig(k, draw(rng, 0.0, 1.0)))
    hidden_noise = {h.identifier: h.params for h in hidden}
    noise_user = [NoiseConfig(k, p) for k, p in known.items() if k not in hidden_noise]
    truth_noise = [NoiseConfig(k, hidden_noise.get(k, p)) for k, p in known.items()]
    temperature = TemperatureConfig(
        case_tau_s=float(rng.uniform(120.0, 300.0)),
        temp_noise_c=float(
            rng.uniform(0.005, 0.015)
            if any(spec.fine_thermometer for spec in specs)
            else rng.uniform(0.01, 0.04)
        ),
    )
    for effect in effects:
        drawn = _draw_effect(effect, rng, protocol, slope)
        if drawn is not None:
            hidden.append(drawn)
    effect_order = list(EFFECTS)
    truth_effects = sorted(
        [poly, *[h for h in hidden if h.identifier in EFFECTS]],
        key=lambda e: effect_order.index(e.identifier),
    )
    base = PhysicsConfig(
        recording=RecordingConfig(sample_rate_hz=fs, sensor="scenario"),
        protocol=protocol,
        temperature=temperature,
        effects=(poly,),
        noise=tuple(noise_user),
    )
    truth = replace(base, effects=tuple(truth_effects), noise=tuple(truth_noise))
    truth = _conceal(truth, base, hidden, seed)
    sim = replace(base, noise=tuple(n if n.identifier != WHITE_NOISE else truth.noise[0] for n in noise_user))
    name = "+".join(effects) or "clean"
    return Scenario(f"{name}#{seed}", seed, truth, sim, tuple(hidden))


def contribution(
    truth: PhysicsConfig, base: PhysicsConfig, hidden: Sequence[EffectConfig], seed: int
) -> np.ndarray:
    """What the concealed effects add to the model's error, sample by sample (mg).

    For bias effects the change of the true drift; for an effect on the thermometer reading
    (``temp_quantization``) the error of the polynomial evaluated on that reading; for a noise
    term (``rate_random_walk``) the noise it adds.
    """
    with_rec = simulate(truth, seed)
    out = (
        with_rec.columns["true_drift_mg"]
        - simulate(replace(truth, effects=base.effects), seed).columns["true_drift_mg"]
    )
    poly = base.effects[0].params
    if any(h.identifier in EFFECTS and EFFECTS[h.identifier].thermometer is not None for h in hidden):

        def curve(T: np.ndarray) -> np.ndarray:
            return polynomial(
                T, poly["c0_mg"], poly["c1_mg_per_c"], poly["c2_mg_per_c2"], poly["c3_mg_per_c3"]
            )

        out = out + curve(with_rec.columns["true_temp_c"]) - curve(with_rec.columns["temp_c"])
    hidden_noise = {h.identifier for h in hidden if h.identifier in NOISE}
    if hidden_noise:
        without = replace(truth, noise=tuple(n for n in truth.noise if n.identifier not in hidden_noise))
        out = out + with_rec.columns["true_noise_mg"] - simulate(without, seed).columns["true_noise_mg"]
    return out


def _conceal(
    truth: PhysicsConfig, base: PhysicsConfig, hidden: Sequence[EffectConfig], seed: int
) -> PhysicsConfig:
    """Raise the white noise so that the per-sample noise is at least the concealed contribution."""
    if not hidden:
        return truth
    peak = float(np.max(np.abs(contribution(truth, base, hidden, seed))))
    fs = truth.recording.sample_rate_hz
    white = truth.noise[0]
    sigma = white.params["n_mg_rt_s"] * math.sqrt(fs)
    if peak <= sigma:
        return truth
    noise = (NoiseConfig(white.identifier, {"n_mg_rt_s": 1.05 * peak / math.sqrt(fs)}), *truth.noise[1:])
    return replace(truth, noise=noise)


def concealment(scenario: Scenario) -> dict[str, float]:
    """Peak contribution over per-sample noise, and the share of its variance a cubic in T absorbs."""
    truth, sim = scenario.truth, scenario.sim
    c = contribution(truth, sim, scenario.hidden, scenario.seed)
    rec = simulate(truth, scenario.seed)
    temp = rec.columns["temp_c"]
    sigma = truth.noise[0].params["n_mg_rt_s"] * math.sqrt(truth.recording.sample_rate_hz)
    u = (temp - 25.0) / 50.0
    X = np.column_stack([u**k for k in range(4)])
    beta, *_ = np.linalg.lstsq(X, c, rcond=None)
    left = c - X @ beta
    total = float(np.sum((c - 0.0) ** 2))
    return {
        "peak_over_sigma": float(np.max(np.abs(c))) / sigma,
        "absorbed_fraction": 1.0 - float(np.sum(left**2)) / total if total > 0 else 0.0,
    }
