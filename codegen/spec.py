"""Read a checkpoint's payload into plain float specs, with one-line errors naming the field.

The checkpoint itself is loaded and validated by :func:`trainer.checkpoint.load_checkpoint`; this
module only checks what the code generator relies on (shapes, finiteness, orderings, positive
scales) so that a malformed payload is a :class:`UserError`, never a traceback or silent garbage.
Each C family parses its own payload (its unit's parser, codegen/families/); this module reads the
common fields and dispatches.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from codegen import family
from codegen.family import ModelSpec
from trainer import methods as registry
from trainer.fields import DottedFields as _Fields


@dataclass(frozen=True)
class Checkpoint:
    """What the generator needs from a loaded checkpoint."""

    method: str
    model: ModelSpec
    valid_temp_range_c: tuple[float, float]
    unit: str = "mg"  # the channel's unit (mg, dps, pa): the step's integers are 1/16000 of it


def parse_checkpoint(checkpoint: dict[str, Any], source: str) -> Checkpoint:
    """Typed specs of a checkpoint already validated by ``load_checkpoint``."""
    root = _Fields(source, checkpoint, "")
    method = checkpoint.get("method")
    entry = registry.REGISTRY.get(method) if isinstance(method, str) else None
    if entry is None or entry.renderer is None or entry.renderer not in family.names():
        supported = [m for m in registry.with_renderer() if registry.get(m).renderer in family.names()]
        root.fail(f"method {method!r} has no code generator (supported: {', '.join(supported)})")
    assert entry is not None and entry.renderer is not None
    lo, hi = root.numbers("valid_temp_range_c", 2)
    if not lo <= hi:
        root.fail(f"field 'valid_temp_range_c' must be increasing, got {[lo, hi]}")
    payload = root.sub("payload")
    model = family.get(entry.renderer).parse(root, payload, entry.name)
    return Checkpoint(entry.name, model, (lo, hi), channel_unit_of(checkpoint))


def channel_unit_of(checkpoint: dict[str, Any]) -> str:
    """The unit of the channel the model was fitted on (``train_stats.unit``: mg, dps, pa, the units of
    ``trainer.data.channels``, each with its words in :mod:`codegen.step_units`); a model without one
    (an accelerometer's, or a file written before channels) is in mg."""
    from trainer.data.channels import DEFAULT_UNIT, UNIT_LABELS
    from trainer.train_stats import TrainStats

    unit = TrainStats.of_checkpoint(checkpoint).unit or DEFAULT_UNIT
    return unit if unit in UNIT_LABELS else DEFAULT_UNIT
