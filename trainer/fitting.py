"""Fit a compensator by method name and describe the training data it saw."""

from __future__ import annotations

from typing import Any

import numpy as np

from trainer import methods
from trainer.compensator import Compensator
from trainer.data.recording import Recording
from trainer.errors import UserError


def make_compensator(method: str, options: dict[str, Any] | None = None) -> Compensator:
    """A fresh, unfitted compensator of ``method`` built with keyword ``options``."""
    cls = methods.get(method).cls
    try:
        return cls(**(options or {}))
    except TypeError as exc:
        raise UserError(f"--method {method}: bad option ({exc})") from None


def training_stats(rec: Recording) -> dict[str, Any]:
    """What the checkpoint records about its training data (plain values only)."""
    return {
        "source": rec.source,
        "n_samples": len(rec),
        "sample_rate_hz": float(rec.sample_rate_hz),
        "duration_s": float(rec.time_s[-1] - rec.time_s[0]),
        "temp_min_c": float(np.min(rec.temp_c)),
        "temp_max_c": float(np.max(rec.temp_c)),
        "accel_mean_mg": float(np.mean(rec.accel_mg)),
        "accel_std_mg": float(np.std(rec.accel_mg)),
        **_channel_stats(rec),
    }


def _channel_stats(rec: Recording) -> dict[str, Any]:
    """The sensor channel ``accel_mg`` came from and its device id, when the recording says so.

    Flight-stack parameters (``codegen export --format px4-params``) are keyed by them.
    """
    from trainer.data.flightlog import parse_channel

    name = rec.meta.get("channel", "")
    channel = parse_channel(name)
    if channel is None:
        return {}
    stats: dict[str, Any] = {"channel": name}
    device_id = rec.meta.get(f"device_id_{channel.sensor}{channel.instance}", "")
    if device_id.isdigit():
        stats["device_id"] = int(device_id)
    return stats


def fit_compensator(method: str, train: Recording, options: dict[str, Any] | None = None) -> Compensator:
    """Fit ``method`` on ``train`` with every ground-truth column hidden from it."""
    model = make_compensator(method, options)
    return model.fit(train.without_truth())


def fit_with_stats(
    method: str, train: Recording, options: dict[str, Any] | None = None
) -> tuple[Compensator, dict[str, Any]]:
    """Fit ``method`` and return it with its checkpoint's ``train_stats`` (incl. the fit residual RMS)."""
    model = fit_compensator(method, train, options)
    stats = training_stats(train)
    residual = train.accel_mg - model.predict_drift(train.without_truth())
    stats["fit_residual_rms_mg"] = float(np.sqrt(np.mean((residual - residual.mean()) ** 2)))
    return model, stats
