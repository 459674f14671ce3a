"""The golden model for a quantised model: its C family's (:mod:`codegen.family`)."""

from __future__ import annotations

from codegen.family import Golden, QuantModel, family_of


def golden_for(model: QuantModel) -> Golden:
    """A fresh golden model, initialised like ``NAME_init``."""
    golden = family_of(model).golden(model)
    golden.init()
    return golden
