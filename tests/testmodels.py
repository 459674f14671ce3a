"""Checkpoints for the tests and the benchmark, in the trainer's exact file layout.

DLSTM checkpoints carry random (MATLAB-style initialised, optionally scaled) weights from
:class:`trainer.dlstm.network.PopulationDLSTM` and a front end whose normalisation is computed from a
recording the way docs/realtime.md defines the training pairs; PLA and poly3 are fitted by the
trainer itself. Nothing here is used by ``codegen export`` or ``verify``.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import torch

from codegen.spec import TEMPERATURE_METHODS
from trainer import __version__ as trainer_version
from trainer.baselines.pla import PiecewiseLinear
from trainer.baselines.poly3 import CubicPolynomial
from trainer.checkpoint import FORMAT_NAME, FORMAT_VERSION
from trainer.data.recording import Recording
from trainer.data.smoothing import moving_average, window_samples
from trainer.dlstm.network import PopulationDLSTM
from trainer.errors import atomic_output


def frontend_fields(
    rate_hz: float, *, run_s: float = 0.5, temp_s: float = 5.0, step_s: float = 1.0, train_s: float = 5.0
) -> dict[str, Any]:
    return {
        "rate_hz": float(rate_hz),
        "accel_window": window_samples(run_s, rate_hz),
        "temp_window": window_samples(temp_s, rate_hz),
        "decimation": window_samples(step_s, rate_hz),
        "train_accel_window": window_samples(train_s, rate_hz),
    }


def normalisation_from(rec: Recording, method: str, frontend: dict[str, Any]) -> dict[str, Any]:
    """Mean and std of the network inputs and targets on ``rec`` (docs/realtime.md training pairs)."""
    D = frontend["decimation"]
    u = moving_average(rec.accel_mg, frontend["train_accel_window"])[::D]
    if method in TEMPERATURE_METHODS:
        temp_k = moving_average(rec.temp_c, frontend["temp_window"])[::D]
        rate_k = np.concatenate(([0.0], np.diff(temp_k) * 60.0 * frontend["rate_hz"] / D))
        inputs, targets = np.column_stack([temp_k, rate_k]), u
    else:
        inputs, targets = u[:-1, None], u[1:]
    std = inputs.std(axis=0)
    return {
        "inputs_mean": [float(v) for v in inputs.mean(axis=0)],
        "inputs_std": [float(v) if v > 0 else 1.0 for v in std],
        "output_mean": float(targets.mean()),
        "output_std": float(targets.std()) or 1.0,
    }


def random_weights(
    input_size: int, hidden: int, layers: int, *, seed: int, scale: float = 1.0, init: str = "matlab"
) -> dict[str, torch.Tensor]:
    """One individual of a PopulationDLSTM (the trainer's initialisation), weights times ``scale``."""
    net = PopulationDLSTM(1, input_size, hidden, layers, seed=seed, init=init, dtype=torch.float64)  # type: ignore[arg-type]
    return {k: (v * scale).float() for k, v in net.individual(0).items()}


def dlstm_payload(
    method: str,
    weights: dict[str, torch.Tensor],
    frontend: dict[str, Any],
    normalisation: dict[str, Any],
) -> dict[str, Any]:
    """The payload layout of ``trainer/dlstm/compensators.py``."""
    kind = "temperature" if method in TEMPERATURE_METHODS else "recursive"
    w_x0 = weights["w_x0"]
    norm_fields: dict[str, float]
    if kind == "temperature":
        norm_fields = {
            "temp_mean": normalisation["inputs_mean"][0],
            "temp_std": normalisation["inputs_std"][0],
            "rate_mean": normalisation["inputs_mean"][1],
            "rate_std": normalisation["inputs_std"][1],
            "drift_mean": normalisation["output_mean"],
            "drift_std": normalisation["output_std"],
        }
    else:
        norm_fields = {
            "accel_mean": normalisation["inputs_mean"][0],
            "accel_std": normalisation["inputs_std"][0],
            "output_mean": normalisation["output_mean"],
            "output_std": normalisation["output_std"],
        }
    return {
        "architecture": {
            "input_size": int(w_x0.shape[1]),
            "hidden_size": int(w_x0.shape[0] // 4),
            "num_layers": sum(1 for k in weights if k.startswith("w_h")),
            "output_size": 1,
            "gate_order": "ifgo",
        },
        "weights": {k: v.detach().float().clone() for k, v in weights.items()},
        "frontend": {"kind": kind, **frontend, **norm_fields},
        "normalisation": dict(normalisation),
        "training": {},
    }


def checkpoint_dict(
    method: str, payload: dict[str, Any], valid_temp_range_c: tuple[float, float]
) -> dict[str, Any]:
    return {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "method": method,
        "payload": payload,
        "train_stats": {},
        "valid_temp_range_c": [float(valid_temp_range_c[0]), float(valid_temp_range_c[1])],
        "created_by": f"mems-tdc {trainer_version} (codegen test model)",
    }


def save_checkpoint(checkpoint: dict[str, Any], path: str | os.PathLike[str]) -> None:
    with atomic_output(path) as tmp:
        torch.save(checkpoint, tmp)


def dlstm_checkpoint(
    method: str,
    rec: Recording,
    *,
    hidden: int = 10,
    layers: int = 2,
    seed: int = 0,
    scale: float = 1.0,
    frontend: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """A DLSTM checkpoint with random weights and the front end normalised on ``rec``."""
    fe = frontend or frontend_fields(rec.sample_rate_hz)
    input_size = 2 if method in TEMPERATURE_METHODS else 1
    weights = random_weights(input_size, hidden, layers, seed=seed, scale=scale)
    payload = dlstm_payload(method, weights, fe, normalisation_from(rec, method, fe))
    return checkpoint_dict(method, payload, (float(rec.temp_c.min()), float(rec.temp_c.max())))


def baseline_checkpoint(method: str, rec: Recording) -> dict[str, Any]:
    """PLA or poly3 fitted by the trainer on ``rec``."""
    model = PiecewiseLinear() if method == "pla" else CubicPolynomial()
    model.fit(rec.without_truth())
    return checkpoint_dict(method, model.to_payload(), (float(rec.temp_c.min()), float(rec.temp_c.max())))


def persistence_checkpoint(rec: Recording) -> dict[str, Any]:
    payload = {"frontend": {"kind": "persistence", **frontend_fields(rec.sample_rate_hz)}}
    return checkpoint_dict("persistence", payload, (float(rec.temp_c.min()), float(rec.temp_c.max())))
