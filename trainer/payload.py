"""Strict readers of a checkpoint's ``payload`` fields (a model's ``from_payload``).

``model.pt`` is loaded with ``weights_only=True``, so it holds plain values and tensors, but a hand
edit or another tool can still put text where a flag belongs or reverse a range. ``bool('yes')``,
``int('3')`` and a reversed clamp range used to be accepted and compensate wrongly, or silently not
at all. Each reader raises ``ValueError`` naming ``payload.<field>``; :func:`trainer.checkpoint.model_of`
turns it into one line naming the file, for every command that reads a model (evaluate, report,
codegen export and verify alike).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch


def _where(key: str) -> str:
    return f"payload.{key}"


def flag(payload: Mapping[str, Any], key: str) -> bool:
    value = payload[key]
    if not isinstance(value, bool):
        raise ValueError(f"{_where(key)} must be true or false, got {value!r}")
    return value


def count(payload: Mapping[str, Any], key: str, low: int, high: int | None = None) -> int:
    value = payload[key]
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or value < low
        or (high is not None and value > high)
    ):
        bound = f"{low}..{high}" if high is not None else f">= {low}"
        raise ValueError(f"{_where(key)} must be a whole number {bound}, got {value!r}")
    return value


def number(value: Any, where: str, rule: str = "finite") -> float:
    """A finite real number (an int or a float, not a flag or text) obeying ``rule``, a catalogue
    parameter's (``positive``: > 0, ``nonnegative``: >= 0; :data:`trainer.fields.NUMBER_RULES`)."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{where} must be a finite number, got {value!r}")
    if rule == "positive" and not value > 0:
        raise ValueError(f"{where} must be > 0, got {value!r}")
    if rule == "nonnegative" and not value >= 0:
        raise ValueError(f"{where} must be >= 0, got {value!r}")
    return float(value)


def temp_range(payload: Mapping[str, Any], key: str = "temp_range_c") -> tuple[float, float]:
    """The clamp range: two finite, increasing temperatures (a reversed one clamps everything)."""
    value = payload[key]
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ValueError(f"{_where(key)} must be [low, high] in degC, got {value!r}")
    lo, hi = (number(v, _where(key)) for v in value)
    if not lo < hi:
        raise ValueError(f"{_where(key)} must be increasing, got [{lo:g}, {hi:g}]")
    return lo, hi


def table(payload: Mapping[str, Any], key: str, length: int | None = None) -> np.ndarray:
    """A 1-D tensor of finite numbers (``length`` of them when given) as float64."""
    value = payload[key]
    if not isinstance(value, torch.Tensor) or value.dim() != 1 or not value.is_floating_point():
        got = (
            f"a {value.dim()}-D {value.dtype} tensor"
            if isinstance(value, torch.Tensor)
            else type(value).__name__
        )
        raise ValueError(f"{_where(key)} must be a 1-D tensor of numbers, got {got}")
    array = value.double().numpy()
    if length is not None and array.shape != (length,):
        raise ValueError(f"{_where(key)} must hold {length} values, got {array.size}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{_where(key)} holds a value that is not finite")
    return array
