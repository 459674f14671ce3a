"""Fit a compensator by method name and describe the training data it saw."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from trainer import methods
from trainer.compensator import Compensator
from trainer.data.recording import Recording, data_fingerprint
from trainer.errors import UserError
from trainer.reference import (
    OFFSET_OPTION,
    OffsetPolicy,
    OffsetRecord,
    check_constant,
    reference_temperature,
)
from trainer.train_stats import TrainStats


def make_compensator(method: str, options: dict[str, Any] | None = None) -> Compensator:
    """A fresh, unfitted compensator of ``method`` built with keyword ``options``."""
    cls = methods.get(method).cls
    try:
        return cls(**(options or {}))
    except TypeError as exc:
        raise UserError(f"--method {method}: bad option ({exc})") from None


def training_stats(rec: Recording) -> TrainStats:
    """What the checkpoint records about its training data."""
    return TrainStats(
        source=Path(rec.source).name,  # the file, not the path typed: the same data gives the same model id
        n_samples=len(rec),
        sample_rate_hz=float(rec.sample_rate_hz),
        duration_s=float(rec.time_s[-1] - rec.time_s[0]),
        temp_min_c=float(np.min(rec.temp_c)),
        temp_max_c=float(np.max(rec.temp_c)),
        accel_mean_mg=float(np.mean(rec.accel_mg)),
        accel_std_mg=float(np.std(rec.accel_mg)),
        time_range_s=(float(rec.time_s[0]), float(rec.time_s[-1])),
        data_sha256=data_fingerprint(rec),
        **_channel_stats(rec),
    )


def _channel_stats(rec: Recording) -> dict[str, Any]:
    """The sensor channel ``accel_mg`` came from, its unit and its device id, when the recording
    says so (TrainStats fields ``channel``, ``unit``, ``device_id``).

    Flight-stack parameters (``codegen export --format px4-params``) are keyed by them.
    """
    from trainer.data.dataflash_reader import board_rotation
    from trainer.data.flightlog import parse_channel

    name = rec.meta.get("channel", "")
    channel = parse_channel(name)
    if channel is None:
        return {}
    stats: dict[str, Any] = {"channel": name}
    if "unit" in rec.meta:  # a one-channel view of a multi-channel recording (trainer.data.channels)
        stats["unit"] = rec.meta["unit"]
    device_id = rec.meta.get(f"device_id_{channel.sensor}{channel.instance}", "")
    if device_id.isdigit():
        stats["device_id"] = int(device_id)
    if (rotation := board_rotation(rec.meta)) is not None:
        stats["ahrs_orientation"] = rotation
    return stats


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
    try:
        model.fit(blind)
    except UserError as exc:  # a method's refusal names the recording it could not fit
        text = str(exc)
        raise UserError(text if text.startswith(train.source) else f"{train.source}: {text}") from None
    apply_offset_policy(model, methods.get(method), blind, policy or OffsetPolicy())
    return model


def removes_sustained_input(method: methods.Method) -> bool:
    """A recursive method removes any sustained acceleration (no reference temperature)."""
    return method.family == methods.RECURSIVE


def apply_offset_policy(
    model: Compensator, method: methods.Method, train: Recording, policy: OffsetPolicy
) -> OffsetRecord | None:
    """Shift a fitted temperature-driven ``model`` as ``policy`` says; None for a recursive method.

    The model is fitted with its constant (least squares needs one); the policy then moves the
    constant out through :meth:`Compensator.shift_drift`, which every temperature-driven method
    implements so that the exported C carries the same shift.
    """
    if removes_sustained_input(method):
        return None
    t_ref = reference_temperature(train.temp_c, policy.t_ref_c)
    model.expand_about(t_ref)
    constant = model.drift_at_reference(t_ref, train.sample_rate_hz, train)
    record = OffsetRecord(policy.mode, t_ref, constant)
    check_constant(record, f"{method.name} fitted on {train.source}")
    if record.relative:
        try:
            model.shift_drift(-constant)
        except NotImplementedError:
            raise UserError(
                f"method {method.name!r} cannot model the drift relative to T_ref (its class does not "
                f"implement Compensator.shift_drift); use {OFFSET_OPTION} absolute"
            ) from None
    model.offset = record
    return record


def fit_with_stats(
    method: str,
    train: Recording,
    options: dict[str, Any] | None = None,
    policy: OffsetPolicy | None = None,
) -> tuple[Compensator, TrainStats]:
    """Fit ``method`` and return it with its checkpoint's ``train_stats`` (incl. the fit residual RMS)."""
    model = fit_compensator(method, train, options, policy)
    residual = train.accel_mg - model.predict_drift(train.without_truth())
    rms_mg = float(np.sqrt(np.mean((residual - residual.mean()) ** 2)))
    return model, replace(training_stats(train), fit_residual_rms_mg=rms_mg)
