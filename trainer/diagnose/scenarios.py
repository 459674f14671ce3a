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

HIDDEN_EFFECTS: tuple[str, ...] = (
    "thermal_lag",
    "temp_rate",
    "hysteresis",
    "stress_relaxation",
    "warmup",
    "periodic",
    "bias_step",
    "temp_quantization",
    "rate_random_walk",
)

# Which parameters each effect must recover (time constants and amplitudes), for tests and bench.
CHECKED_PARAMS: dict[str, tuple[str, ...]] = {
    "thermal_lag": ("tau_s",),
    "temp_rate": ("k_mg_per_c_per_min",),
    "hysteresis": ("amp_mg", "width_c"),
    "stress_relaxation": ("gain_mg_per_c", "tau_s"),
    "warmup": ("amp_mg", "tau_s"),
    "periodic": ("amp_mg", "period_s"),
    "bias_step": ("step_mg",),
    "temp_quantization": ("lsb_c",),
    "rate_random_walk": ("k_mg_per_rt_s",),
}


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
    duration = sum(s.duration_s for s in protocol.segments)
    sign = float(rng.choice([-1.0, 1.0]))
    if effect == "thermal_lag":
        return EffectConfig(effect, {"tau_s": float(rng.uniform(60.0, 400.0))})
    if effect == "temp_rate":
        return EffectConfig(effect, {"k_mg_per_c_per_min": sign * float(rng.uniform(0.04, 0.2))})
    if effect == "hysteresis":
        return EffectConfig(
            effect, {"amp_mg": sign * float(rng.uniform(0.05, 0.2)), "width_c": float(rng.uniform(2.0, 6.0))}
        )
    if effect == "stress_relaxation":
        return EffectConfig(
            effect,
            {
                "gain_mg_per_c": sign * float(rng.uniform(0.012, 0.03)),
                "tau_s": float(rng.uniform(1500.0, 4000.0)),
            },
        )
    if effect == "warmup":
        return EffectConfig(
            effect, {"amp_mg": sign * float(rng.uniform(0.5, 1.2)), "tau_s": float(rng.uniform(200.0, 900.0))}
        )
    if effect == "periodic":
        period = float(np.exp(rng.uniform(math.log(20.0), math.log(1500.0))))
        return EffectConfig(
            effect,
            {
                "amp_mg": float(rng.uniform(0.015, 0.06)),
                "period_s": period,
                "phase_rad": float(rng.uniform(-3.1, 3.1)),
            },
        )
    if effect == "bias_step":
        return EffectConfig(
            effect,
            {
                "t_s": float(rng.uniform(0.25, 0.8) * duration),
                "step_mg": sign * float(rng.uniform(0.15, 0.4)),
            },
        )
    if effect == "temp_quantization":
        return EffectConfig(effect, {"lsb_c": float(rng.choice([0.5, 0.625]))})
    return None


def make_scenario(
    effects: Sequence[str], seed: int, *, rates: Sequence[float] = (2.0, 5.0, 10.0)
) -> Scenario:
    """A generated case with ``effects`` concealed (empty: a clean recording)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7919]))
    # Hysteresis needs a reversal and a random walk one that decouples time from temperature (else
    # the polynomial absorbs it); creep needs long holds: the tests use protocols that can show them.
    reversal = bool(rng.random() < 0.75) or "hysteresis" in effects or "rate_random_walk" in effects
    protocol = _protocol(rng, reversal, long_holds="stress_relaxation" in effects)
    fs = float(rng.choice(list(rates)))
    slope = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.05, 0.25))
    if "temp_quantization" in effects:  # a staircase matters only on a steep enough bias curve
        slope = math.copysign(max(abs(slope), 0.2), slope)
    poly = EffectConfig(
        "bias_poly",
        {
            "c0_mg": float(rng.uniform(-1.0, 1.0)),
            "c1_mg_per_c": slope,
            "c2_mg_per_c2": float(rng.uniform(-1.5e-3, 1.5e-3)),
            "c3_mg_per_c3": float(rng.uniform(-8e-6, 8e-6)),
        },
    )
    n_white = float(rng.uniform(0.02, 0.08))
    noise_user = [
        NoiseConfig("white_noise", {"n_mg_rt_s": n_white}),
        NoiseConfig("bias_instability", {"b_mg": float(rng.uniform(0.008, 0.025))}),
    ]
    hidden: list[EffectConfig] = []
    truth_noise = list(noise_user)
    k_rrw = float(rng.uniform(2e-4, 6e-4))
    if "rate_random_walk" in effects:
        k_rrw = float(rng.uniform(3e-3, 6e-3))
        hidden.append(EffectConfig("rate_random_walk", {"k_mg_per_rt_s": k_rrw}))
        truth_noise.append(NoiseConfig("rate_random_walk", {"k_mg_per_rt_s": k_rrw}))
    else:
        noise_user.append(NoiseConfig("rate_random_walk", {"k_mg_per_rt_s": k_rrw}))
        truth_noise.append(NoiseConfig("rate_random_walk", {"k_mg_per_rt_s": k_rrw}))
    temperature = TemperatureConfig(
        case_tau_s=float(rng.uniform(120.0, 300.0)),
        temp_noise_c=float(
            rng.uniform(0.005, 0.015) if "temp_quantization" in effects else rng.uniform(0.01, 0.04)
        ),
    )
    for effect in effects:
        drawn = _draw_effect(effect, rng, protocol, slope)
        if drawn is not None:
            hidden.append(drawn)
    effect_order = ["bias_poly", *[e for e in HIDDEN_EFFECTS]]
    truth_effects = sorted(
        [poly, *[h for h in hidden if h.identifier != "rate_random_walk"]],
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
    sim = replace(
        base, noise=tuple(n if n.identifier != "white_noise" else truth.noise[0] for n in noise_user)
    )
    name = "+".join(effects) or "clean"
    return Scenario(f"{name}#{seed}", seed, truth, sim, tuple(hidden))


def contribution(
    truth: PhysicsConfig, base: PhysicsConfig, hidden: Sequence[EffectConfig], seed: int
) -> np.ndarray:
    """What the concealed effects add to the model's error, sample by sample (mg).

    For bias effects the change of the true drift; for ``temp_quantization`` the error of the
    polynomial evaluated on the staircase reading; for ``rate_random_walk`` the walk itself.
    """
    with_rec = simulate(truth, seed)
    out = (
        with_rec.columns["true_drift_mg"]
        - simulate(replace(truth, effects=base.effects), seed).columns["true_drift_mg"]
    )
    poly = base.effects[0].params
    if any(h.identifier == "temp_quantization" for h in hidden):

        def curve(T: np.ndarray) -> np.ndarray:
            d = T - 25.0
            return poly["c0_mg"] + d * (
                poly["c1_mg_per_c"] + d * (poly["c2_mg_per_c2"] + d * poly["c3_mg_per_c3"])
            )

        out = out + curve(with_rec.columns["true_temp_c"]) - curve(with_rec.columns["temp_c"])
    if any(h.identifier == "rate_random_walk" for h in hidden):
        without = replace(truth, noise=tuple(n for n in truth.noise if n.identifier != "rate_random_walk"))
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
    noise = (NoiseConfig("white_noise", {"n_mg_rt_s": 1.05 * peak / math.sqrt(fs)}), *truth.noise[1:])
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
