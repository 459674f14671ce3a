"""The golden model for a quantised model: one independent numpy implementation per method and
schedule (:mod:`codegen.golden`, :mod:`codegen.golden_spread`), chosen here so that neither module
imports the other's dispatch."""

from __future__ import annotations

from codegen.golden import GoldenPhysics, GoldenPla, GoldenPoly3, GoldenStream, _Golden
from codegen.golden_spread import GoldenStreamSpread
from codegen.quantize import QPhysics, QPla, QPoly3, QuantModel


def golden_for(model: QuantModel) -> _Golden:
    """A fresh golden model, initialised like ``NAME_init``."""
    golden: _Golden
    if isinstance(model, QPla):
        golden = GoldenPla(model)
    elif isinstance(model, QPoly3):
        golden = GoldenPoly3(model)
    elif isinstance(model, QPhysics):
        golden = GoldenPhysics(model)
    elif model.layers and model.schedule == "spread":
        golden = GoldenStreamSpread(model)
    else:
        golden = GoldenStream(model)
    golden.init()
    return golden
