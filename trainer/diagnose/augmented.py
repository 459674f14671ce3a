"""The augmented simulation: the user's configuration with the fitted and the found effects."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from trainer.data.channels import channel_unit
from trainer.data.recording import Recording
from trainer.diagnose.blocks import BlockData
from trainer.diagnose.gls import NOISE_CANDIDATES
from trainer.diagnose.model import ModelFit, catalogue_effects
from trainer.diagnose.profile import Profile
from trainer.physics.catalogue import DEFINITIONS, NOISE, WHITE_NOISE
from trainer.physics.catalogue.base import catalogue_params
from trainer.physics.catalogue.units import CATALOGUE_UNIT
from trainer.physics.config import ChannelConfig, NoiseConfig, PhysicsConfig, ProtocolConfig, RecordingConfig
from trainer.physics.effects import EFFECT_PARAMETERS
from trainer.physics.profiles import SegmentSpec

RAMP_MIN_C = 0.01  # a "ramp" segment that moves less than this (degC) is written as a hold
TEMP_DIGITS = 4  # setpoints in the written protocol (degC)


def augmented_config(
    sim: PhysicsConfig | None, final: ModelFit, data: BlockData, profile: Profile, rec: Recording
) -> PhysicsConfig:
    """The user's simulation with the fitted (and found) effects, ready for ``trainer simulate``.

    A non-mg channel's physics goes into its ``[channels.<name>]`` table (parameters in its unit);
    the user's other tables are kept.
    """
    unit, name = channel_unit(rec), rec.meta.get("channel")
    own = sim.for_channel(name, unit) if sim is not None else None
    config = _augmented(own, final, data, profile, rec)
    if unit == CATALOGUE_UNIT or name is None:
        return config
    channel = ChannelConfig(name, config.effects, config.noise)
    base = sim if sim is not None else replace(config, effects=(), noise=())
    return base.with_channel(channel)


def _augmented(
    sim: PhysicsConfig | None, final: ModelFit, data: BlockData, profile: Profile, rec: Recording
) -> PhysicsConfig:
    effects = catalogue_effects(final)
    order = list(EFFECT_PARAMETERS)
    effects = sorted(effects, key=lambda e: order.index(e.identifier))
    noise_values = final.noise_params()
    noise = [NoiseConfig(WHITE_NOISE, dict(noise_values[WHITE_NOISE]))]
    for name in NOISE_CANDIDATES:
        if name in noise_values:
            noise.append(NoiseConfig(name, dict(noise_values[name])))
    for index, term in enumerate(final.terms):  # deterministic noise trends, fitted as columns
        definition = DEFINITIONS[term.identifier]
        if definition.finder.noise_role == "trend":
            noise.append(
                NoiseConfig(term.identifier, catalogue_params(definition, term, final.linear(index)))
            )
    if sim is not None:  # the user's noise terms the finder does not model are kept, first
        kept = [n for n in sim.noise if NOISE[n.identifier].finder.noise_role is None]
        return replace(sim, effects=tuple(effects), noise=(*kept, *noise))
    start_c, specs = _protocol(data, profile, rec)
    sensor = rec.meta.get("sensor", "diagnosed").strip() or "diagnosed"
    return PhysicsConfig(
        recording=RecordingConfig(sample_rate_hz=data.fs, sensor=sensor.splitlines()[0]),
        protocol=ProtocolConfig("custom", start_c, tuple(specs)),
        effects=tuple(effects),
        noise=tuple(noise),
    )


def _protocol(data: BlockData, profile: Profile, rec: Recording) -> tuple[float, list[SegmentSpec]]:
    """The recorded temperature profile as protocol segments (chamber column if there is one)."""
    temp = data.temperature(True)
    chamber = rec.columns.get("chamber_c")
    specs: list[SegmentSpec] = []

    def temp_at(t_s: float) -> float:
        if chamber is not None:
            return float(np.interp(t_s, rec.time_s - rec.time_s[0], chamber))
        return float(np.interp(t_s, data.t, temp))

    current = temp_at(0.0)
    start_c = current
    for seg in profile.segments:
        duration = seg.end_s - seg.start_s
        end_c = temp_at(seg.end_s - 1e-6)
        label = seg.label
        if (label == "ramp_up" and end_c <= current + RAMP_MIN_C) or (
            label == "ramp_down" and end_c >= current - RAMP_MIN_C
        ):
            label = "hold"
        if label in ("soak", "hold"):
            end_c = temp_at(0.5 * (seg.start_s + seg.end_s)) if chamber is None else end_c
        specs.append(SegmentSpec(label, duration, round(end_c, TEMP_DIGITS)))
        current = end_c
    return round(start_c, TEMP_DIGITS), specs
