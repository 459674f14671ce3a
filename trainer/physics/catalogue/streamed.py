"""The effects the physics compensator streams: one registry line per streamed effect.

Each entry is the :class:`~trainer.physics.catalogue.streaming.StreamedEffect` of an effect's
``<effect>_stream.py``; the float stream (``trainer/greybox``) and the C export (``codegen``) loop
over it. Registry order is catalogue order (the ``--effects`` list); a step runs the effects by
phase, in registry order within a phase (:func:`in_step_order`). :func:`register` adds one at run
time (a test's throwaway effect), as :mod:`trainer.methods` does for methods.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from trainer.physics.catalogue import (
    hysteresis_offset_stream,
    hysteresis_stream,
    stress_relaxation_stream,
    temp_rate_stream,
    thermal_lag_stream,
    warmup_stream,
)
from trainer.physics.catalogue.streaming import BRANCH, FixedPoint, StreamedEffect

STREAMED: dict[str, StreamedEffect] = {
    m.STREAMED.identifier: m.STREAMED
    for m in (
        thermal_lag_stream,
        temp_rate_stream,
        hysteresis_stream,
        hysteresis_offset_stream,
        stress_relaxation_stream,
        warmup_stream,
    )
}


def register(effect: StreamedEffect) -> StreamedEffect:
    """Add a streamed effect (its catalogue definition must be registered too)."""
    if effect.identifier in STREAMED:
        raise ValueError(f"{effect.identifier} is streamed already")
    STREAMED[effect.identifier] = effect
    return effect


def unregister(identifier: str) -> None:
    del STREAMED[identifier]


def in_step_order(identifiers: Iterable[str]) -> list[StreamedEffect]:
    """The streamed effects among ``identifiers``, each once, in the order one step runs them."""
    once = list(dict.fromkeys(identifiers))
    return [STREAMED[once[i]] for i in instances_in_step_order(once)]


def instance_suffixes(identifiers: Sequence[str]) -> tuple[str, ...]:
    """The suffix of each term's state words, in the order given: ``""`` for an effect's first
    instance, ``"_2"``, ``"_3"``, ... for later ones. A sum of branch offsets of several widths
    carries one play operator per width; each keeps its own words (``play``, ``play_2``, ...) in the
    float stream, the golden model and the C state alike."""
    seen: dict[str, int] = {}
    out = []
    for identifier in identifiers:
        seen[identifier] = seen.get(identifier, 0) + 1
        out.append("" if seen[identifier] == 1 else f"_{seen[identifier]}")
    return tuple(out)


def instances_in_step_order(identifiers: Sequence[str]) -> list[int]:
    """Indices of the streamed effects among ``identifiers`` in the order one step runs them: by
    phase, registry order within a phase, instances of one effect in the order given."""
    order = list(STREAMED)
    wanted = [i for i, k in enumerate(identifiers) if k in STREAMED]
    return sorted(wanted, key=lambda i: (STREAMED[identifiers[i]].phase, order.index(identifiers[i]), i))


def c_terms() -> list[FixedPoint]:
    """Every C term of the registry, once each (effects that are the same C share one), in step order:
    the layout of an IMU module's physics tables and state."""
    terms: dict[str, FixedPoint] = {}
    for effect in in_step_order(STREAMED):
        if effect.fixed is not None:
            terms.setdefault(effect.fixed.name, effect.fixed)
    return list(terms.values())


def c_options() -> list[str]:
    """The option bits of the registry's C terms (what the polynomial reads), in step order."""
    options = (e.fixed.option for e in in_step_order(STREAMED) if e.fixed is not None)
    return list(dict.fromkeys(o for o in options if o is not None))


def play_words() -> frozenset[str]:
    """The state words that are a play operator's output (the branch effects', phase BRANCH): at
    power-on they start at a model's play start when it has one, else at the first temperature."""
    return frozenset(word for e in STREAMED.values() if e.phase == BRANCH for word in e.state)
