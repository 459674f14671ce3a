"""Fit a compensator by method name and describe the training data it saw."""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

from trainer import methods
from trainer.compensator import Compensator
from trainer.data.recording import Recording
from trainer.errors import UserError
from trainer.reference import OffsetPolicy, apply_offset_policy


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
        "time_range_s": [float(rec.time_s[0]), float(rec.time_s[-1])],
        "data_sha256": data_fingerprint(rec),
    }


def data_fingerprint(rec: Recording) -> str:
    """sha256 of the time, temperature and acceleration columns: the same data, whatever the file."""
    digest = hashlib.sha256()
    for name in ("time_s", "temp_c", "accel_mg"):
        digest.update(np.ascontiguousarray(rec.columns[name], dtype=np.float64).tobytes())
    return digest.hexdigest()


def fit_compensator(
    method: str,
    train: Recording,
    options: dict[str, Any] | None = None,
    policy: OffsetPolicy | None = None,
) -> Compensator:
    """Fit ``method`` on ``train`` with every ground-truth column hidden from it, then apply the
    offset policy (relative to ``T_ref`` by default; :mod:`trainer.reference`)."""
    model = make_compensator(method, options)
    blind = train.without_truth()
    model.fit(blind)
    apply_offset_policy(model, methods.get(method), blind, policy or OffsetPolicy())
    return model
