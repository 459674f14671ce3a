"""``model.pt``: save and load fitted compensators without ever executing code from the file.

The file is a ``torch.save`` of a plain dict::

    {"format": "mems-tdc-model", "format_version": 1, "method": "pla", "payload": {...},
     "train_stats": {...}, "valid_temp_range_c": [lo, hi], "created_by": "mems-tdc 0.2.0",
     "offset": {"mode": "relative", "t_ref_c": ..., "drift_at_t_ref_mg": ...}}

``train_stats`` is the plain dict of a :class:`trainer.train_stats.TrainStats` (readers take it
with ``TrainStats.of_checkpoint``); ``offset`` (optional; absent for recursive methods and older
files) is the :class:`trainer.reference.OffsetRecord` of a temperature-driven model.

and is always read with ``torch.load(weights_only=True)``, which refuses pickled code.

:func:`load_checkpoint` is the one validation of these fields for every command that loads a model
(``evaluate``, ``report``, ``codegen export/verify``, ``--format px4-params``): a hand-edited or damaged file
(NaN coefficients, ``train_stats = None``, a one-number valid range) is a one-line UserError naming
the field, never a traceback inside a command nor a report scored with NaN.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import pickle
import re
import sys
import warnings
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from trainer import __version__, methods
from trainer.compensator import Compensator
from trainer.data.recording_io import RECORDING_SUFFIXES
from trainer.errors import UserError, atomic_output
from trainer.fields import DottedFields, show
from trainer.reference import OffsetRecord
from trainer.train_stats import FIELD_CHECKS, TrainStats, is_count

FORMAT_NAME = "mems-tdc-model"
_UNSUPPORTED_GLOBAL = re.compile(r"Unsupported global: GLOBAL ([\w.]+)")
FORMAT_VERSION = 1


SELECTED_PAYLOAD = "payload_sha256"  # the selection record's fingerprint of the payload it chose


def payload_fingerprint(payload: dict[str, Any]) -> str:
    """sha256 of a payload's canonical JSON (keys sorted, arrays as lists): a model file whose
    parameters were edited after the fit no longer matches its selection record."""

    def plain(value: Any) -> Any:
        if isinstance(value, torch.Tensor | np.ndarray):
            return value.tolist()
        if isinstance(value, np.generic):
            return value.item()
        raise TypeError(f"{type(value).__name__} in a payload")

    text = json.dumps(payload, sort_keys=True, default=plain)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def cross_validated_selection(checkpoint: dict[str, Any]) -> dict[str, Any] | None:
    """The checkpoint's selection record when its cross-validation is of this payload (a record written
    before the fingerprint existed counts as one); None when there is none or the payload was changed."""
    record = (checkpoint.get("train_stats") or {}).get("selection")
    if not isinstance(record, dict):
        return None
    kept = record.get(SELECTED_PAYLOAD)
    if kept is not None and kept != payload_fingerprint(checkpoint["payload"]):
        return None
    return record


def save_model(
    model: Compensator,
    path: str | os.PathLike[str],
    *,
    train_stats: TrainStats,
    valid_temp_range_c: tuple[float, float],
) -> None:
    """Write ``model`` to ``path`` atomically (no partial file on failure). An ``auto`` model's
    selection record gets the fingerprint of the payload it chose (:func:`payload_fingerprint`): its
    cross-validation speaks for these parameters, and for no others."""
    payload = model.to_payload()
    stats = train_stats.to_dict()
    if isinstance(stats.get("selection"), dict):
        stats["selection"] = {**stats["selection"], SELECTED_PAYLOAD: payload_fingerprint(payload)}
    checkpoint = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "method": methods.name_of(model),
        "payload": payload,
        "train_stats": stats,
        "valid_temp_range_c": [float(valid_temp_range_c[0]), float(valid_temp_range_c[1])],
        "created_by": f"mems-tdc {__version__}",
    }
    if model.offset is not None:
        checkpoint["offset"] = model.offset.to_dict()
    # torch.save names the archive's root folder after the file it writes; serialising to memory
    # first keeps that name fixed ("archive"), so the same model gives byte-identical files
    # (and the same model_id in the generated C) whatever the output path.
    buffer = io.BytesIO()
    torch.save(_canonical(checkpoint), buffer)
    with atomic_output(path) as tmp:
        tmp.write_bytes(buffer.getvalue())


def _canonical(value: Any) -> Any:
    """The same values in fresh containers, with interned strings. Pickle writes an object it has
    written before as a reference to it, by identity: equal strings that are one object in one run
    and two in another made different files of the same model (a physics model fitted in a
    ``compare --jobs 2`` worker and sent back: 3245 bytes, 3181 in the process). Containers are
    never shared here, and every repeated string is one object, whichever way the values were made."""
    if isinstance(value, dict):
        return {_canonical(k): _canonical(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_canonical(v) for v in value]
    if isinstance(value, tuple):
        return tuple(_canonical(v) for v in value)
    if type(value) is str:
        return sys.intern(value)
    return value


ZIP_END_RECORD = b"PK\x05\x06"  # a zip's end of central directory: 22 bytes and its comment, last in the file


def _check_archive(p: Path) -> None:
    """A model file is the zip archive ``torch.save`` writes, ending where its end record says: a file
    that is no zip (text, a legacy pickle) or has bytes after the archive (two files concatenated, a
    transfer that appended) is refused before torch reads it, with what it is."""
    if not zipfile.is_zipfile(p):
        raise UserError(
            f"{p}: not a readable model file: a model is the zip archive 'trainer fit' writes, and this is not "
            "one (truncated, a text file, or another format?)"
        )
    size = p.stat().st_size
    with p.open("rb") as f:
        f.seek(max(0, size - (22 + 0xFFFF)))
        tail = f.read()
    at = tail.rfind(ZIP_END_RECORD)
    end = size - len(tail) + at + 22 + int.from_bytes(tail[at + 20 : at + 22], "little")
    if at >= 0 and end < size:
        raise UserError(
            f"{p}: not a readable model file: {size - end} bytes follow the model's zip archive (two files "
            "joined, or a damaged copy)"
        )


def load_checkpoint(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read and validate the checkpoint dict; every failure is a one-line :class:`UserError`."""
    p = Path(path)
    if p.is_dir():
        from trainer.options.channels import INDEX_FILE  # trainer fit --channels: one model per channel

        raise UserError(
            f"{p}: a directory, not a model file; for the per-channel models 'trainer fit --channels' wrote "
            f"there, add --channels all (or a list such as accel0_z,gyro0_x), or give the model files ({p}/*.pt: "
            "trainer report takes several)"
            if (p / INDEX_FILE).is_file()
            else f"{p}: a directory, not a model file (model.pt, written by 'trainer fit')"
        )
    if not p.is_file():
        what = "not a regular file (a device or a pipe)" if p.exists() else "no such model file"
        raise UserError(f"{p}: {what}; a model file is the model.pt 'trainer fit' writes")
    if p.suffix.lower() in RECORDING_SUFFIXES:
        raise UserError(
            f"{p}: a recording ({p.suffix.lower()}), not a model file written by 'trainer fit' "
            "(arguments swapped? the model comes before the recording)"
        )
    _check_archive(p)
    try:
        with (
            warnings.catch_warnings()
        ):  # torch warns about raw pickles; the refusal below says it in one line
            warnings.simplefilter("ignore")
            checkpoint = torch.load(p, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        # torch's message advises loading with weights_only=False: never forward that advice.
        found = _UNSUPPORTED_GLOBAL.search(str(exc))
        what = (
            f"a Python object of type {found.group(1)}"
            if found
            else "content beyond tensors and plain values"
        )
        raise UserError(
            f"{p}: refused to load: it holds {what} (not a plain mems-tdc checkpoint; such files are never unpickled)"
        ) from None
    except Exception as exc:  # torch's loader raises many types on damaged files; all mean the same
        raise UserError(
            f"{p}: not a readable model file (truncated or corrupted: {type(exc).__name__})"
        ) from None
    # compared only once known to be plain values: a tensor there has no truth value
    if not isinstance(checkpoint, dict) or not (
        isinstance(checkpoint.get("format"), str) and checkpoint["format"] == FORMAT_NAME
    ):
        raise UserError(f"{p}: not a mems-tdc model (field 'format' is not '{FORMAT_NAME}')")
    version = checkpoint.get("format_version")
    if not (is_count(version) and version == FORMAT_VERSION):
        raise UserError(
            f"{p}: field 'format_version' is {version!r}; this tool reads version {FORMAT_VERSION}"
        )
    _check_fields(checkpoint, str(p))
    return checkpoint


# No fitted number (a coefficient, temperature, time constant, pressure, network weight) comes near
# this; a payload number beyond it overflows float64 on evaluation (a cube of 1e103 is inf).
PAYLOAD_MAGNITUDE_LIMIT = 1e12


def _check_fields(checkpoint: dict[str, Any], source: str) -> None:
    """Every field a command reads, typed and finite: one place for every command."""
    root = DottedFields(source, checkpoint, "")
    for key in ("method", "payload", "train_stats", "valid_temp_range_c"):
        root.raw(key)
    method = checkpoint["method"]
    if not isinstance(method, str) or method not in methods.REGISTRY:
        raise UserError(
            f"{source}: field 'method' is {show(method)}, not one of {', '.join(sorted(methods.REGISTRY))}"
        )
    payload = root.sub("payload")  # a dict
    stats = root.sub("train_stats")
    for key, (valid, what) in FIELD_CHECKS.items():  # each optional; when present, what readers expect
        if stats.has(key) and not valid(stats.data[key]):
            stats.fail(f"field 'train_stats.{key}' must be {what}, got {show(stats.data[key])}")
    _check_channel_unit(stats)
    lo, hi = root.numbers("valid_temp_range_c", 2)
    if not lo <= hi:
        root.fail(f"field 'valid_temp_range_c' must be increasing, got {[lo, hi]}")
    if payload.has("temp_range_c"):  # the range the model clamps its temperature to
        clamp_lo, clamp_hi = payload.numbers("temp_range_c", 2)
        if clamp_lo <= clamp_hi and (
            lo < clamp_lo - 1e-9 or hi > clamp_hi + 1e-9
        ):  # reversed: the payload's reader says so
            root.fail(
                f"field 'valid_temp_range_c' {lo:g} .. {hi:g} degC reaches beyond 'payload.temp_range_c' "
                f"{clamp_lo:g} .. {clamp_hi:g} degC, where the model clamps its temperature: the module would "
                "not flag the extrapolation (a damaged or hand-edited model file)"
            )
    if "offset" in checkpoint:
        try:
            offset = OffsetRecord.from_dict(checkpoint["offset"])
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"{source}: field 'offset' is malformed ({exc})") from None
        # one fit sets both: a polynomial about one T_ref with its constant taken at another is garbage
        if payload.has("t_ref_c") and payload.number("t_ref_c") != offset.t_ref_c:
            root.fail(
                f"field 'payload.t_ref_c' {payload.number('t_ref_c'):g} degC differs from 'offset.t_ref_c' "
                f"{offset.t_ref_c:g} degC, which one fit sets alike (a damaged or hand-edited model file)"
            )
    bad = _first_non_finite(checkpoint["payload"], "payload")
    if bad is not None:
        raise UserError(
            f"{source}: field {bad!r} holds NaN, inf or a number beyond {PAYLOAD_MAGNITUDE_LIMIT:g} "
            "(a damaged or hand-edited model file)"
        )


def _check_channel_unit(stats: DottedFields) -> None:
    """``train_stats.unit`` is one the tool knows and is the unit its ``channel`` is named for: a
    gyroscope model relabelled ``accel0_x`` was exported as an accelerometer, its deg/s read as mg."""
    from trainer.data.channels import DEFAULT_UNIT, UNITS
    from trainer.data.flightlog import parse_channel

    unit = stats.data.get("unit")
    if unit is not None and unit not in UNITS:
        stats.fail(f"field 'train_stats.unit' is {show(unit)}, not one of {', '.join(UNITS)}")
    channel = stats.data.get("channel")
    parsed = parse_channel(channel) if isinstance(channel, str) else None
    if parsed is not None and parsed.unit != (unit or DEFAULT_UNIT):
        stats.fail(
            f"field 'train_stats.channel' {channel!r} is a channel in {parsed.unit}, but 'train_stats.unit' "
            f"says {unit or DEFAULT_UNIT} (a damaged or hand-edited model file)"
        )


def _first_non_finite(value: Any, name: str) -> str | None:
    """Dotted name of the first number (float, tensor, array) in ``value`` that is NaN, inf or
    beyond :data:`PAYLOAD_MAGNITUDE_LIMIT`."""
    if isinstance(value, dict):
        items: Any = ((f"{name}.{k}", v) for k, v in value.items())
    elif isinstance(value, list | tuple):
        items = ((f"{name}[{i}]", v) for i, v in enumerate(value))
    elif isinstance(value, torch.Tensor):
        bounded = bool((value.abs() <= PAYLOAD_MAGNITUDE_LIMIT).all())  # False for NaN
        return name if value.is_floating_point() and not bounded else None
    elif isinstance(value, np.ndarray):
        return (
            name
            if value.dtype.kind == "f" and not bool((np.abs(value) <= PAYLOAD_MAGNITUDE_LIMIT).all())
            else None
        )
    elif isinstance(value, float):
        return None if abs(value) <= PAYLOAD_MAGNITUDE_LIMIT else name
    else:
        return None
    for child, item in items:
        found = _first_non_finite(item, child)
        if found is not None:
            return found
    return None


def model_of(checkpoint: dict[str, Any], path: str | os.PathLike[str]) -> Compensator:
    """The compensator of a validated checkpoint dict, its payload read strictly
    (:mod:`trainer.payload`): every command that reads a model (evaluate, report, codegen) refuses the
    same hand edits in the same line."""
    cls = methods.REGISTRY[checkpoint["method"]].cls
    try:
        return cls.from_payload(checkpoint["payload"])
    except KeyError as exc:
        raise UserError(
            f"{path}: field 'payload' is malformed for method {checkpoint['method']!r} (key {exc} is missing)"
        ) from None
    # wrong types or shapes (RuntimeError: torch's, e.g. the truth value of a tensor where a flag belongs)
    except (TypeError, ValueError, IndexError, AttributeError, RuntimeError, UserError) as exc:
        raise UserError(
            f"{path}: field 'payload' is malformed for method {checkpoint['method']!r} ({exc})"
        ) from None


def load_model(path: str | os.PathLike[str]) -> tuple[Compensator, dict[str, Any]]:
    """The fitted compensator and its checkpoint dict."""
    checkpoint = load_checkpoint(path)
    model = model_of(checkpoint, path)
    if "offset" in checkpoint:
        model.offset = OffsetRecord.from_dict(checkpoint["offset"])
    return model, checkpoint
