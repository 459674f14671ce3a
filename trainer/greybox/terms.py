"""Which catalogue effects the physics compensator carries, and the ``--effects`` list.

Only compensable effects (a property of the sensor, :attr:`Effect.compensable`) that the streaming
form implements go into the compensator. Others the finder may name (a bias step, a chamber
oscillation, a quantised thermometer) are fitted alongside as nuisance terms, so they do not bias
the parameters, and are not compensated.
"""

from __future__ import annotations

from trainer.errors import UserError
from trainer.physics.catalogue import (
    EFFECTS,
    excluded,
    hysteresis,
    hysteresis_offset,
    stress_relaxation,
    temp_rate,
    thermal_lag,
    warmup,
)

# The terms the streaming form (:mod:`trainer.greybox.stream`) implements, in catalogue order.
STREAMABLE: tuple[str, ...] = tuple(
    m.DEFINITION.identifier
    for m in (thermal_lag, temp_rate, hysteresis, hysteresis_offset, stress_relaxation, warmup)
)
# Needs the time since power-on from the firmware: only with ``--warmup`` (or listed).
NEEDS_POWER_ON_TIME: frozenset[str] = frozenset({warmup.DEFINITION.identifier})
LAG = thermal_lag.DEFINITION.identifier
RATE = temp_rate.DEFINITION.identifier
HYSTERESIS = hysteresis.DEFINITION.identifier
HYSTERESIS_OFFSET = hysteresis_offset.DEFINITION.identifier
CREEP = stress_relaxation.DEFINITION.identifier
WARMUP = warmup.DEFINITION.identifier

assert all(EFFECTS[name].compensable for name in STREAMABLE)


def compensated(identifier: str, *, warmup_allowed: bool) -> bool:
    """Whether a found effect goes into the compensator (else it is a nuisance term of the fit)."""
    if identifier not in STREAMABLE:
        return False
    return warmup_allowed or identifier not in NEEDS_POWER_ON_TIME


def parse_effects(text: str, option: str = "--effects") -> tuple[str, ...]:
    """``auto`` -> ``()`` sentinel handled by the caller; else a comma list of streamable effects."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise UserError(f"{option}: empty list; give 'auto' or effects from {', '.join(STREAMABLE)}")
    for name in names:
        if name not in EFFECTS:
            raise UserError(f"{option}: unknown effect {name!r}; choose from {', '.join(STREAMABLE)}")
        if name not in STREAMABLE:
            raise UserError(
                f"{option}: {name} is not a drift the physics compensator models; choose from {', '.join(STREAMABLE)}"
            )
    if len(set(names)) != len(names):
        raise UserError(f"{option}: an effect is listed twice in {text!r}")
    for i, first in enumerate(names):
        for second in names[i + 1 :]:
            if excluded(first, second):
                raise UserError(f"{option}: {first} and {second} describe the same physics twice; keep one")
    return names
