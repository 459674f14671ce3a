"""The physics family's checkpoint parser: the grey-box model's parameters and its sample rate."""

from __future__ import annotations

from dataclasses import dataclass

from trainer.fields import DottedFields as _Fields
from trainer.greybox.stream import PhysicsModel
from trainer.physics.catalogue.streamed import STREAMED


@dataclass(frozen=True)
class PhysicsSpec:
    """The grey-box model's plain parameters and the sample rate its filters are discretised for."""

    method: str
    model: PhysicsModel
    rate_hz: float  # the training recording's (train_stats.sample_rate_hz)


def parse_physics(root: _Fields, payload: _Fields, method: str) -> PhysicsSpec:
    """Parameters through the trainer's own payload reader (one definition of the layout)."""
    from trainer.checkpoint import model_of  # the trainer's strict reading: evaluate's refusals, here too
    from trainer.greybox.compensator import PhysicsCompensator

    rate_hz = root.sub("train_stats").number("sample_rate_hz", positive=True)
    compensator = model_of(root.data, root.source)
    assert isinstance(compensator, PhysicsCompensator)
    model = compensator.model
    for term in model.terms:  # a streamed effect without a C form: refused, or left out when it adds nothing
        streamed = STREAMED[term.identifier]
        why = (
            None
            if streamed.fixed is not None or streamed.unexported is None
            else streamed.unexported(term.params)
        )
        if why is not None:
            root.fail(why)
    lo, hi = model.temp_range_c
    if not lo < hi:
        root.fail(f"field 'payload.temp_range_c' must be increasing, got {[lo, hi]}")
    return PhysicsSpec(method, model, rate_hz)
