"""``model.pt``: save and load fitted compensators without ever executing code from the file.

The file is a ``torch.save`` of a plain dict::

    {"format": "mems-tdc-model", "format_version": 1, "method": "pla", "payload": {...},
     "train_stats": {...}, "valid_temp_range_c": [lo, hi], "created_by": "mems-tdc 0.1.0",
     "offset": {"mode": "relative", "t_ref_c": ..., "drift_at_t_ref_mg": ...}}

``offset`` (optional; absent for recursive methods and older files) is the
:class:`trainer.reference.OffsetRecord` of a temperature-driven model.

and is always read with ``torch.load(weights_only=True)``, which refuses pickled code.
"""

from __future__ import annotations

import io
import os
import pickle
import re
from pathlib import Path
from typing import Any

import torch

from trainer import __version__, methods
from trainer.compensator import Compensator
from trainer.errors import UserError, atomic_output
from trainer.reference import OffsetRecord

FORMAT_NAME = "mems-tdc-model"
_UNSUPPORTED_GLOBAL = re.compile(r"Unsupported global: GLOBAL ([\w.]+)")
FORMAT_VERSION = 1


def save_model(
    model: Compensator,
    path: str | os.PathLike[str],
    *,
    train_stats: dict[str, Any],
    valid_temp_range_c: tuple[float, float],
) -> None:
    """Write ``model`` to ``path`` atomically (no partial file on failure)."""
    checkpoint = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "method": methods.name_of(model),
        "payload": model.to_payload(),
        "train_stats": train_stats,
        "valid_temp_range_c": [float(valid_temp_range_c[0]), float(valid_temp_range_c[1])],
        "created_by": f"mems-tdc {__version__}",
    }
    if model.offset is not None:
        checkpoint["offset"] = model.offset.to_dict()
    # torch.save names the archive's root folder after the file it writes; serialising to memory
    # first keeps that name fixed ("archive"), so the same model gives byte-identical files
    # (and the same model_id in the generated C) whatever the output path.
    buffer = io.BytesIO()
    torch.save(checkpoint, buffer)
    with atomic_output(path) as tmp:
        tmp.write_bytes(buffer.getvalue())


def load_checkpoint(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read and validate the checkpoint dict; every failure is a one-line :class:`UserError`."""
    p = Path(path)
    if not p.is_file():
        raise UserError(f"{p}: no such model file")
    try:
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
    if not isinstance(checkpoint, dict) or checkpoint.get("format") != FORMAT_NAME:
        raise UserError(f"{p}: not a mems-tdc model (field 'format' is not '{FORMAT_NAME}')")
    version = checkpoint.get("format_version")
    if version != FORMAT_VERSION:
        raise UserError(
            f"{p}: field 'format_version' is {version!r}; this tool reads version {FORMAT_VERSION}"
        )
    for key in ("method", "payload", "train_stats", "valid_temp_range_c"):
        if key not in checkpoint:
            raise UserError(f"{p}: field '{key}' is missing")
    if checkpoint["method"] not in methods.REGISTRY:
        raise UserError(
            f"{p}: field 'method' is {checkpoint['method']!r}, not one of {', '.join(sorted(methods.REGISTRY))}"
        )
    return checkpoint


def load_model(path: str | os.PathLike[str]) -> tuple[Compensator, dict[str, Any]]:
    """The fitted compensator and its checkpoint dict."""
    checkpoint = load_checkpoint(path)
    cls = methods.REGISTRY[checkpoint["method"]].cls
    try:
        model = cls.from_payload(checkpoint["payload"])
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise UserError(
            f"{path}: field 'payload' is malformed for method {checkpoint['method']!r} ({exc})"
        ) from None
    if "offset" in checkpoint:
        try:
            model.offset = OffsetRecord.from_dict(checkpoint["offset"])
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"{path}: field 'offset' is malformed ({exc})") from None
    return model, checkpoint
