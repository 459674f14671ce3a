"""``warmup`` streamed: ``amp exp(-t / tau_s)``, t the time since power-on (which the C step API does
not have: the export refuses a model that carries it)."""

from __future__ import annotations

import math

from trainer.physics.catalogue.streaming import ADDITIVE, Params, Sample, StreamedEffect
from trainer.physics.catalogue.warmup import DEFINITION


def _step(p: Params, _: tuple[float, ...], v: dict[str, float], s: Sample) -> float:
    return p["amp_mg"] * math.exp(-s.time_s / p["tau_s"])


def _unexported(p: Params) -> str | None:
    if p["amp_mg"] == 0.0:
        return None
    return (
        "the physics model includes the warm-up term, which needs the time since power-on; the C "
        "export leaves it out: refit without --warmup (the warm-up is then left to the output)"
    )


STREAMED = StreamedEffect(
    identifier=DEFINITION.identifier,
    phase=ADDITIVE,
    state=(),
    prepare=lambda p, dt_s: (),
    step=_step,
    needs_power_on_time=True,
    unexported=_unexported,
)
