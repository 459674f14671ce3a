"""The checkpoint's ``train_stats``: what a model records about the data it was fitted on.

One declaration of every field: its name, type, order on disk and the check
:func:`trainer.checkpoint.load_checkpoint` applies (:data:`FIELD_CHECKS`). Every field is optional
(hand-made and older files carry few); :meth:`TrainStats.to_dict` writes the present ones in the
declared order, so the saved ``model.pt`` is the plain dict (``torch.load(weights_only=True)``)
and byte-identical to the one written before this record existed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, Self

Check = tuple[Callable[[Any], bool], str]  # (is the stored value valid, what it must be)


def is_text(value: Any) -> bool:
    return isinstance(value, str)


def is_count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def is_finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _is_rate(value: Any) -> bool:
    return is_finite(value) and value > 0


def _is_time_range(value: Any) -> bool:
    return (
        isinstance(value, list | tuple)
        and len(value) == 2
        and all(map(is_finite, value))
        and value[0] <= value[1]
    )


def _is_dict(value: Any) -> bool:
    return isinstance(value, dict)


# the figures of trainer.scoring.fit_holdout.held_out_record, in the order of trainer.scoring.verdict.Figures
# (as trainer.fleet.stages.DRIFT_LEFT_KEYS; None: not measured, e.g. all in range, or
# not finite: a model whose output is not, which the guard then refuses as such)
HELD_OUT_FIGURES = (
    "model_rms",
    "uncompensated_rms",
    "model_in_range_rms",
    "uncompensated_in_range_rms",
    "noise_floor",
)


def _is_held_out(value: Any) -> bool:
    """What ``codegen export`` judges: a spec and the figures, each a finite number or None (a hand-edited
    record with a figure of text would otherwise pass the guard unjudged)."""
    return (
        isinstance(value, dict)
        and is_text(value.get("holdout"))
        and all(
            k in value and (value[k] is None or (is_finite(value[k]) and value[k] >= 0))
            for k in HELD_OUT_FIGURES
        )
        and value["uncompensated_rms"] is not None  # the recording's own output: always measured
    )


TEXT: Check = (is_text, "a string")
COUNT: Check = (is_count, "a whole number >= 0")
FINITE: Check = (is_finite, "a finite number")
RATE: Check = (_is_rate, "a finite number > 0")
TIME_RANGE: Check = (_is_time_range, "[start, end], finite and increasing")
DICT: Check = (_is_dict, "a dict")
HELD_OUT: Check = (
    _is_held_out,
    f"a dict of 'holdout' (text) and {', '.join(HELD_OUT_FIGURES)} (each a finite RMS >= 0, or null where not "
    "measured: the model's output not finite, or no sample outside the trained range; uncompensated_rms never null)",
)


def _checked(check: Check) -> dict[str, Check]:
    """A field's metadata: its load-time check (every field defaults to None, absent from the file)."""
    return {"check": check}


@dataclass(frozen=True)
class TrainStats:
    """The training data of a model (:func:`trainer.fitting.training_stats` fills it)."""

    source: str | None = field(default=None, metadata=_checked(TEXT))
    n_samples: int | None = field(default=None, metadata=_checked(COUNT))
    sample_rate_hz: float | None = field(default=None, metadata=_checked(RATE))
    duration_s: float | None = field(default=None, metadata=_checked(FINITE))
    temp_min_c: float | None = field(default=None, metadata=_checked(FINITE))
    temp_max_c: float | None = field(default=None, metadata=_checked(FINITE))
    accel_mean_mg: float | None = field(default=None, metadata=_checked(FINITE))
    accel_std_mg: float | None = field(default=None, metadata=_checked(FINITE))
    time_range_s: tuple[float, float] | None = field(default=None, metadata=_checked(TIME_RANGE))
    # trainer.data.recording.data_fingerprint of the training rows (proves a held-out overlap)
    data_sha256: str | None = field(default=None, metadata=_checked(TEXT))
    # the recording's 'channel' metadata (e.g. accel0_z), a one-channel view's unit, the sensor's
    # flight-stack device id (trainer.data.channels, codegen --format px4-params)
    channel: str | None = field(default=None, metadata=_checked(TEXT))
    unit: str | None = field(default=None, metadata=_checked(TEXT))
    device_id: int | None = field(default=None, metadata=_checked(COUNT))
    # ArduPilot's AHRS_ORIENTATION of a DataFlash recording (non-zero: vehicle axes, not the sensor's)
    ahrs_orientation: int | None = field(default=None, metadata=_checked(COUNT))
    fit_residual_rms_mg: float | None = field(default=None, metadata=_checked(FINITE))
    # trainer.selection.selection_record: the cross-validation that chose an auto model
    selection: dict[str, Any] | None = field(default=None, metadata=_checked(DICT))
    # the candidate asked for by name (trainer fit --method poly1): its registered method (poly3)
    # loads it, this is what the user reads (trainer.selection.shown_name)
    variant: str | None = field(default=None, metadata=_checked(TEXT))
    # a model fitted with --holdout: its drift left on the part held out, beside the uncompensated output's
    # (trainer.scoring.fit_holdout.held_out_record); codegen export refuses one worse than none there
    held_out: dict[str, Any] | None = field(default=None, metadata=_checked(HELD_OUT))

    @property
    def temp_range_c(self) -> tuple[float, float]:
        """The training temperatures' span (every fit records it; absent only in hand-made files)."""
        if self.temp_min_c is None or self.temp_max_c is None:
            raise ValueError("train_stats records no temperature range (temp_min_c, temp_max_c)")
        return (self.temp_min_c, self.temp_max_c)

    def to_dict(self) -> dict[str, Any]:
        """The plain dict stored in ``model.pt``: present fields only, in declared order."""
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                out[f.name] = list(value) if f.name == "time_range_s" else value
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Self:
        """The record of a stored dict (validated by :func:`trainer.checkpoint.load_checkpoint`);
        keys this version does not know are left out."""
        values = {name: data[name] for name in FIELD_CHECKS if data.get(name) is not None}
        if "time_range_s" in values:
            lo, hi = values["time_range_s"]
            values["time_range_s"] = (float(lo), float(hi))
        return cls(**values)

    @classmethod
    def of_checkpoint(cls, checkpoint: Mapping[str, Any]) -> Self:
        """The record of a checkpoint dict; empty where it has no ``train_stats`` table."""
        data = checkpoint.get("train_stats")
        return cls.from_dict(data) if isinstance(data, Mapping) else cls()


# name -> check, in the order of the record: what load_checkpoint validates
FIELD_CHECKS: dict[str, Check] = {f.name: f.metadata["check"] for f in fields(TrainStats)}
