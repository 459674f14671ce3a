"""Which catalogue effects the physics compensator carries, and the ``--effects`` list.

Only compensable effects (a property of the sensor, :attr:`Effect.compensable`) that the streaming
form implements go into the compensator. Others the finder may name (a bias step, a chamber
oscillation, a quantised thermometer) are fitted alongside as nuisance terms, so they do not bias
the parameters, and are not compensated.
"""

from __future__ import annotations

from trainer.errors import UserError
from trainer.physics.catalogue import EFFECTS, excluded
from trainer.physics.catalogue.streamed import STREAMED

# The terms the streaming form implements (the registry of streamed effects), in catalogue order;
# these import-time views are for the planner, the functions below read the registry itself.
STREAMABLE: tuple[str, ...] = tuple(STREAMED)
# Need the time since power-on from the firmware: only with ``--warmup`` (or listed).
NEEDS_POWER_ON_TIME: frozenset[str] = frozenset(k for k, e in STREAMED.items() if e.needs_power_on_time)

assert all(EFFECTS[name].compensable for name in STREAMABLE)


def compensated(identifier: str, *, warmup_allowed: bool) -> bool:
    """Whether a found effect goes into the compensator (else it is a nuisance term of the fit)."""
    effect = STREAMED.get(identifier)
    if effect is None:
        return False
    return warmup_allowed or not effect.needs_power_on_time


def parse_effects(text: str, option: str = "--effects") -> tuple[str, ...]:
    """``auto`` -> ``()`` sentinel handled by the caller; else a comma list of streamable effects."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    streamable = ", ".join(STREAMED)
    if not names:
        raise UserError(f"{option}: empty list; give 'auto' or effects from {streamable}")
    for name in names:
        if name not in EFFECTS:
            raise UserError(f"{option}: unknown effect {name!r}; choose from {streamable}")
        if name not in STREAMED:
            raise UserError(
                f"{option}: {name} is not a drift the physics compensator models; choose from {streamable}"
            )
    if len(set(names)) != len(names):
        raise UserError(f"{option}: an effect is listed twice in {text!r}")
    for i, first in enumerate(names):
        for second in names[i + 1 :]:
            if excluded(first, second):
                raise UserError(f"{option}: {first} and {second} describe the same physics twice; keep one")
    return names
