"""The physics catalogue: one definition per identifier, one module per definition.

Identifiers, parameter names, units and plausible ranges are the contract of
``shared/specs/physics-catalogue.md``. Each module (``thermal_lag.py``, ...) holds everything the
tool knows about its identifier: parameters, the simulator's formula, how the mismatch finder
models, searches, judges and reports it, and how the test bench conceals it
(:mod:`trainer.physics.catalogue.base` describes the fields). Every other module loops over the
registry below; adding an effect is one new module plus one line here. What the physics
compensator and its C export need of an effect it streams is in a sibling unit,
``<effect>_stream.py``, listed in :mod:`trainer.physics.catalogue.streamed`.
"""

from __future__ import annotations

from trainer.physics.catalogue import (
    bias_instability,
    bias_poly,
    bias_step,
    hysteresis,
    hysteresis_offset,
    periodic,
    quantization_noise,
    rate_ramp,
    rate_random_walk,
    scale_factor_tc,
    stress_relaxation,
    temp_quantization,
    temp_rate,
    thermal_lag,
    warmup,
    white_noise,
)
from trainer.physics.catalogue.base import T_REF_C, Effect, NoiseTerm, Param
from trainer.physics.catalogue.units import ChannelScale, plausible_range

# Catalogue order. Configurations are written in it (so it is part of their equality), the noise
# order is also the order of the simulator's random streams (append new terms at the end), and the
# finder tries its candidates in it (the search is order-dependent).
EFFECTS: dict[str, Effect] = {
    m.DEFINITION.identifier: m.DEFINITION
    for m in (
        bias_poly,
        thermal_lag,
        temp_rate,
        hysteresis,
        hysteresis_offset,
        stress_relaxation,
        warmup,
        periodic,
        bias_step,
        temp_quantization,
        scale_factor_tc,
    )
}
NOISE: dict[str, NoiseTerm] = {
    m.DEFINITION.identifier: m.DEFINITION
    for m in (quantization_noise, white_noise, bias_instability, rate_random_walk, rate_ramp)
}
DEFINITIONS: dict[str, Effect | NoiseTerm] = {**EFFECTS, **NOISE}

# ---------------------------------------------------------------------- derived views: simulator
EFFECT_PARAMETERS: dict[str, tuple[Param, ...]] = {k: d.params for k, d in EFFECTS.items()}
NOISE_PARAMETERS: dict[str, tuple[Param, ...]] = {k: d.params for k, d in NOISE.items()}
MULTI_INSTANCE: frozenset[str] = frozenset(k for k, d in EFFECTS.items() if d.multi_instance)
TEMPERATURE_CHAIN: frozenset[str] = frozenset(k for k, d in EFFECTS.items() if d.temperature_chain)

# ---------------------------------------------------------------------- derived views: finder
BACKBONE: str = next(k for k, d in EFFECTS.items() if d.finder.backbone)
WHITE_NOISE: str = next(k for k, d in NOISE.items() if d.finder.noise_role == "white")
# correlated noise terms of the block covariance (the finder's noise model besides white noise)
COVARIANCE_NOISE: tuple[str, ...] = tuple(k for k, d in NOISE.items() if d.finder.noise_role == "covariance")
NOISE_EFFECTS: frozenset[str] = frozenset(COVARIANCE_NOISE)
# Effects, then the deterministic noise trend, then the covariance noise terms: the finder judges
# the noise terms first and the deterministic candidates in this order.
CANDIDATE_ORDER: tuple[str, ...] = (
    *(k for k, d in EFFECTS.items() if d.finder.search),
    *(k for k, d in NOISE.items() if d.finder.search and d.finder.noise_role == "trend"),
    *(k for k, d in NOISE.items() if d.finder.search and d.finder.noise_role == "covariance"),
)
ADVICE: dict[str, str] = {k: DEFINITIONS[k].finder.advice for k in CANDIDATE_ORDER}
PLAUSIBLE: dict[tuple[str, str], tuple[float, float]] = {
    (k, p.name): p.plausible
    for k, d in DEFINITIONS.items()
    for p in d.params
    if p.plausible is not None and p.flagged
}
PARAMETERS: dict[tuple[str, str], Param] = {(k, p.name): p for k, d in DEFINITIONS.items() for p in d.params}


def flagged_range(
    identifier: str, name: str, scale: ChannelScale | None = None
) -> tuple[float, float] | None:
    """The plausible range a fitted ``identifier.name`` is flagged against on a channel of ``scale``
    (None: mg, the catalogue's own range; see :func:`~trainer.physics.catalogue.units.plausible_range`)."""
    param = PARAMETERS.get((identifier, name))
    return None if param is None else plausible_range(param, scale)


CONFUSABLE: dict[str, tuple[str, ...]] = {
    k: DEFINITIONS[k].finder.confounders for k in CANDIDATE_ORDER if DEFINITIONS[k].finder.confounders
}
SEPARATING_SIGNATURE: dict[frozenset[str], str] = {
    frozenset({k, other}): text
    for k, d in DEFINITIONS.items()
    for other, text in d.finder.separations.items()
}


def excluded(first: str, second: str) -> bool:
    """Whether two identifiers describe the same physics twice (either definition's ``excludes``)."""
    a, b = EFFECTS.get(first), EFFECTS.get(second)
    return (a is not None and second in a.excludes) or (b is not None and first in b.excludes)


def nonlinear_defaults(identifier: str) -> tuple[float, ...]:
    """The catalogue defaults of an identifier's nonlinear parameters (a linear search holds them)."""
    definition = DEFINITIONS[identifier]
    params = {p.name: p for p in definition.params}
    return tuple(float(params[name].default or 0.0) for name, _ in definition.finder.nonlinear)


def _check() -> None:
    """Cross-references between definitions name real identifiers; each separation is written once."""
    pairs = [frozenset({k, o}) for k, d in DEFINITIONS.items() for o in d.finder.separations]
    assert len(pairs) == len(set(pairs)), "a separating signature is defined twice"
    for k, d in DEFINITIONS.items():
        for other in (*d.finder.confounders, *d.finder.separations, *getattr(d, "excludes", ())):
            assert other in DEFINITIONS, f"{k}: unknown identifier {other!r}"


_check()

__all__ = [
    "ADVICE",
    "BACKBONE",
    "CANDIDATE_ORDER",
    "CONFUSABLE",
    "COVARIANCE_NOISE",
    "DEFINITIONS",
    "EFFECTS",
    "EFFECT_PARAMETERS",
    "MULTI_INSTANCE",
    "NOISE",
    "NOISE_EFFECTS",
    "NOISE_PARAMETERS",
    "PARAMETERS",
    "PLAUSIBLE",
    "SEPARATING_SIGNATURE",
    "TEMPERATURE_CHAIN",
    "T_REF_C",
    "WHITE_NOISE",
    "excluded",
    "flagged_range",
    "nonlinear_defaults",
]
