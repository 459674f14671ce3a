"""The stream family's checkpoint parser: the DLSTM payload and the persistence front end.

DLSTM payloads follow ``trainer/dlstm/compensators.py``: weights named as
``PopulationDLSTM.individual`` (``w_x0, w_h0, b0, ..., w_out, b_out``; the ``layer0.w_x`` /
``head.w`` names of docs/realtime.md are accepted too), ``frontend`` (kind, rate, windows,
decimation) and ``normalisation`` (``inputs_mean``, ``inputs_std``, ``output_mean``,
``output_std``, in mg, degC and degC/min).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from trainer import methods as registry
from trainer.dlstm.realtime import PERSISTENCE_KIND, RECURSIVE_KIND, TEMPERATURE_KIND
from trainer.fields import DottedFields as _Fields

MAX_WINDOW = 1 << 20  # keeps window sums times 2**8 inside int64


@dataclass(frozen=True)
class FrontEndSpec:
    """Streaming front end of docs/realtime.md, in samples."""

    kind: str  # RECURSIVE_KIND | TEMPERATURE_KIND
    rate_hz: float
    accel_window: int
    temp_window: int
    decimation: int
    inputs_mean: tuple[float, ...]
    inputs_std: tuple[float, ...]
    output_mean: float  # mg
    output_std: float  # mg


@dataclass(frozen=True)
class LayerSpec:
    w_x: np.ndarray  # (4H, in) float64
    w_h: np.ndarray  # (4H, H)
    b: np.ndarray  # (4H,)


@dataclass(frozen=True)
class DlstmModelSpec:
    method: str
    frontend: FrontEndSpec
    layers: tuple[LayerSpec, ...]
    head_w: np.ndarray  # (H,)
    head_b: float

    @property
    def hidden_size(self) -> int:
        return self.layers[0].w_h.shape[1]

    @property
    def input_size(self) -> int:
        return self.layers[0].w_x.shape[1]


@dataclass(frozen=True)
class PersistenceSpec:
    method: str
    frontend: FrontEndSpec


def frontend_kind(method: registry.Method) -> str:
    """The ``payload.frontend.kind`` a streaming method's checkpoint carries."""
    if method.renderer == "mean-stream":
        return PERSISTENCE_KIND
    return TEMPERATURE_KIND if method.family == registry.TEMPERATURE_DRIVEN else RECURSIVE_KIND


def _frontend(root: _Fields, payload: _Fields, method: str) -> FrontEndSpec:
    fe = payload.sub("frontend")
    kind = fe.raw("kind")
    expected = frontend_kind(registry.REGISTRY[method])
    if kind != expected:
        root.fail(f"field 'payload.frontend.kind' is {kind!r}; method {method!r} needs {expected!r}")
    n_inputs = 2 if kind == TEMPERATURE_KIND else 1
    rate_hz = fe.number("rate_hz", positive=True)
    accel_window = fe.integer("accel_window", 1, MAX_WINDOW)
    temp_window = fe.integer("temp_window", 1, MAX_WINDOW)
    decimation = fe.integer("decimation", 1, MAX_WINDOW)
    if kind == PERSISTENCE_KIND:
        return FrontEndSpec(
            RECURSIVE_KIND,
            rate_hz,
            accel_window,
            temp_window,
            decimation,
            inputs_mean=(0.0,),
            inputs_std=(1.0,),
            output_mean=0.0,
            output_std=1.0,
        )
    norm = payload.sub("normalisation")
    return FrontEndSpec(
        kind,
        rate_hz,
        accel_window,
        temp_window,
        decimation,
        inputs_mean=norm.numbers("inputs_mean", n_inputs),
        inputs_std=norm.numbers("inputs_std", n_inputs, positive=True),
        output_mean=norm.number("output_mean"),
        output_std=norm.number("output_std", positive=True),
    )


_DOC_NAMES = {"head.w": "w_out", "head.b": "b_out"}


def _weight_names(weights: dict[str, Any]) -> dict[str, Any]:
    """Accept docs/realtime.md's ``layer0.w_x`` names as well as the trainer's ``w_x0``."""
    renamed = {}
    for key, value in weights.items():
        if key in _DOC_NAMES:
            key = _DOC_NAMES[key]
        elif key.startswith("layer") and "." in key:
            layer, _, leaf = key[len("layer") :].partition(".")
            key = f"{leaf}{layer}"
        renamed[key] = value
    return renamed


def parse_dlstm(root: _Fields, payload: _Fields, method: str) -> DlstmModelSpec:
    frontend = _frontend(root, payload, method)
    arch = payload.sub("architecture")
    n_in = 2 if frontend.kind == TEMPERATURE_KIND else 1
    input_size = arch.integer("input_size", n_in, n_in)
    hidden = arch.integer("hidden_size", 1, 256)
    num_layers = arch.integer("num_layers", 1, 16)
    arch.integer("output_size", 1, 1)
    if arch.data.get("gate_order", "ifgo") != "ifgo":
        root.fail(f"field 'payload.architecture.gate_order' is {arch.data['gate_order']!r}, expected 'ifgo'")
    raw_weights = payload.raw("weights")
    if not isinstance(raw_weights, dict):
        root.fail("field 'payload.weights' must be a dict of tensors")
    weights = _Fields(root.source, _weight_names(raw_weights), "payload.weights")
    layers = []
    for layer in range(num_layers):
        n = input_size if layer == 0 else hidden
        layers.append(
            LayerSpec(
                weights.array(f"w_x{layer}", (4 * hidden, n)),
                weights.array(f"w_h{layer}", (4 * hidden, hidden)),
                weights.array(f"b{layer}", (4 * hidden,)),
            )
        )
    head_w = weights.array("w_out", (1, hidden))[0]
    head_b = float(weights.array("b_out", (1,))[0])
    return DlstmModelSpec(method, frontend, tuple(layers), head_w, head_b)


def parse_persistence(root: _Fields, payload: _Fields, method: str) -> PersistenceSpec:
    return PersistenceSpec(method, _frontend(root, payload, method))
