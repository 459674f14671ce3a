"""Checkpoints for the tests and the benchmark, in the trainer's exact file layout.

DLSTM checkpoints carry random (MATLAB-style initialised, optionally scaled) weights from
:class:`trainer.dlstm.network.PopulationDLSTM` and a front end whose normalisation is computed from a
recording the way docs/realtime.md defines the training pairs; PLA and poly3 are fitted by the
trainer itself. Nothing here is used by ``codegen export`` or ``verify``.
"""

from __future__ import annotations

import io
import os
from typing import Any

import numpy as np
import torch

from codegen.families.stream.spec import frontend_kind
from trainer import __version__ as trainer_version
from trainer import methods as registry
from trainer.checkpoint import FORMAT_NAME, FORMAT_VERSION
from trainer.data.recording import Recording
from trainer.data.smoothing import moving_average, window_samples
from trainer.dlstm.network import PopulationDLSTM
from trainer.dlstm.realtime import PERSISTENCE_KIND, TEMPERATURE_KIND
from trainer.errors import atomic_output


def ramp_recording(seed: int, source: str, *, rate_hz: float = 5.0, temp_noise_c: float = 0.0) -> Recording:
    """3000 samples of a -10 -> 50 degC ramp with a quadratic drift and 0.01 mg of noise: what the
    export tests fit their small models on (``temp_noise_c``: thermometer noise, drawn first)."""
    rng = np.random.default_rng(seed)
    temp = np.linspace(-10.0, 50.0, 3000)
    if temp_noise_c:
        temp = temp + rng.normal(0, temp_noise_c, temp.size)
    signal = 0.02 * (temp - 20.0) + 1e-4 * (temp - 20.0) ** 2 + rng.normal(0, 0.01, temp.size)
    return Recording(
        {"time_s": np.arange(temp.size) / rate_hz, "temp_c": temp, "accel_mg": signal},
        {"sample_rate_hz": f"{rate_hz:g}"},
        source,
    )


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
    if frontend_kind(registry.REGISTRY[method]) == TEMPERATURE_KIND:
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
    """The payload layout of ``trainer/dlstm/compensators.py`` (normalisation written once)."""
    w_x0 = weights["w_x0"]
    return {
        "architecture": {
            "input_size": int(w_x0.shape[1]),
            "hidden_size": int(w_x0.shape[0] // 4),
            "num_layers": sum(1 for k in weights if k.startswith("w_h")),
            "output_size": 1,
            "gate_order": "ifgo",
        },
        "weights": {k: v.detach().float().clone() for k, v in weights.items()},
        "frontend": {"kind": frontend_kind(registry.REGISTRY[method]), **frontend},
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
    """Byte-identical files for the same checkpoint (the archive's root folder named as
    trainer.checkpoint.save_model names it, not after a temporary file)."""
    buffer = io.BytesIO()
    torch.save(checkpoint, buffer)
    with atomic_output(path) as tmp:
        tmp.write_bytes(buffer.getvalue())


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
    input_size = 2 if frontend_kind(registry.REGISTRY[method]) == TEMPERATURE_KIND else 1
    weights = random_weights(input_size, hidden, layers, seed=seed, scale=scale)
    payload = dlstm_payload(method, weights, fe, normalisation_from(rec, method, fe))
    return checkpoint_dict(method, payload, (float(rec.temp_c.min()), float(rec.temp_c.max())))


def baseline_checkpoint(method: str, rec: Recording) -> dict[str, Any]:
    """A memoryless method (PLA, poly3) fitted by the trainer on ``rec`` with its default options."""
    model = registry.get(method).cls()
    model.fit(rec.without_truth())
    return checkpoint_dict(method, model.to_payload(), (float(rec.temp_c.min()), float(rec.temp_c.max())))


def persistence_checkpoint(rec: Recording) -> dict[str, Any]:
    """The reference predictor's checkpoint (the registry's method with the mean-stream renderer)."""
    method = next(m.name for m in registry.entries() if m.renderer == "mean-stream")
    payload = {"frontend": {"kind": PERSISTENCE_KIND, **frontend_fields(rec.sample_rate_hz)}}
    return checkpoint_dict(method, payload, (float(rec.temp_c.min()), float(rec.temp_c.max())))


# A grey-box model with every term the C export carries (catalogue units; sizes like the real run's).
PHYSICS_EFFECTS: dict[str, dict[str, float]] = {
    "bias_poly": {"c0_mg": 0.4, "c1_mg_per_c": 0.15, "c2_mg_per_c2": 1e-3, "c3_mg_per_c3": -5e-6},
    "thermal_lag": {"tau_s": 120.0},
    "temp_rate": {"k_mg_per_c_per_min": 0.3, "tau_s": 60.0},
    "hysteresis_offset": {"amp_mg": 0.8, "width_c": 6.0},
    "stress_relaxation": {"gain_mg_per_c": 0.02, "tau_s": 3000.0},
}


def physics_checkpoint(
    rec: Recording, effects: dict[str, dict[str, float]] | None = None, **_: Any
) -> dict[str, Any]:
    """A physics checkpoint with given parameters (no fit), the training range and rate of ``rec``."""
    from trainer.greybox.compensator import PhysicsCompensator
    from trainer.physics.effects import EffectConfig

    model = PhysicsCompensator()
    model.effects = tuple(EffectConfig(k, dict(v)) for k, v in (effects or PHYSICS_EFFECTS).items())
    model.temp_range_c = (float(rec.temp_c.min()), float(rec.temp_c.max()))
    model.report = {}
    checkpoint = checkpoint_dict("physics", model.to_payload(), model.temp_range_c)
    checkpoint["train_stats"] = {"sample_rate_hz": float(rec.sample_rate_hz)}
    return checkpoint


def checkpoint_for(method: str, rec: Recording, **kwargs: Any) -> dict[str, Any]:
    """A test checkpoint of any method with a renderer (``kwargs`` go to :func:`dlstm_checkpoint`)."""
    renderer = registry.get(method).renderer
    if renderer in ("pla", "cubic"):
        return baseline_checkpoint(method, rec)
    if renderer == "mean-stream":
        return persistence_checkpoint(rec)
    if renderer == "physics":
        return physics_checkpoint(rec)
    return dlstm_checkpoint(method, rec, **kwargs)


def representatives() -> tuple[str, ...]:
    """The first method of each distinct generated C (renderer and front-end kind), in renderer order."""
    chosen: dict[tuple[str, str], str] = {}
    for method in registry.entries():
        if method.renderer is not None:
            kind = frontend_kind(method) if method.renderer.endswith("stream") else ""
            chosen.setdefault((method.renderer, kind), method.name)
    order: dict[str, int] = {renderer: k for k, renderer in enumerate(registry.RENDERERS)}
    return tuple(name for (renderer, _), name in sorted(chosen.items(), key=lambda kv: order[kv[0][0]]))
