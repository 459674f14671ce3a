"""``codegen export``: model.pt -> NAME.h, NAME.c, NAME.manifest.json, all or nothing.

Everything is computed in memory first; the files are then written into a staging directory and
swapped in as one set (trainer/atomic_dir.py), so a failure or a kill leaves no half-written output
and never a mix of two exports. A file of the module's own (``module_files``: ``NAME.cal.bin`` of an
export with ``--blob``) that an earlier export of NAME left and this one does not write is removed in
the same swap; the folder's other files are kept.
"""

from __future__ import annotations

import hashlib
import os
import sys
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from codegen.family import QuantModel, family_of
from codegen.input_limits import (
    DEFAULT_RAW_LIMITS,
    RawClamp,
    RawLimits,
    check_governed,
    check_raw_limits,
    signal_lsb,
)
from codegen.manifest import build_manifest
from codegen.quantize import quantise_checkpoint
from codegen.rate import ANY_RATE_MILLIHZ, any_rate_note, declared_rate_millihz, retime_checkpoint
from codegen.render import default_name, manifest_json, render_sources, validate_name
from codegen.spec import Checkpoint, parse_checkpoint
from codegen.step_units import STEP_UNITS
from trainer import methods as registry
from trainer.atomic_dir import atomic_directory
from trainer.checkpoint import load_checkpoint, load_model
from trainer.errors import UserError
from trainer.fitting import removes_sustained_input
from trainer.reference import OFFSET_LIMIT_MG, OFFSET_OPTION, OffsetRecord, check_constant, recursive_note
from trainer.train_stats import TrainStats


@dataclass(frozen=True)
class LoadedModel:
    """A checkpoint as the generator sees it: parsed specs, quantised model, file hash."""

    path: Path
    sha256: str
    checkpoint: Checkpoint
    quantised: QuantModel
    notes: tuple[str, ...] = ()  # what the module does with the offset (printed, and in NAME.h)
    shown: str = ""  # the name the user knows the model by (auto's candidate: poly2, physics-branch)
    sensor: str = ""  # what the header's title names (sensor_of): "accelerometer", or a channel's sensor

    @property
    def name(self) -> str:
        return self.shown or self.checkpoint.method

    @property
    def unit(self) -> str:
        """The channel's unit (mg, dps, pa): the step's integers are 1/16000 of it."""
        unit: str = self.quantised.limits.unit
        return unit


def load_for_codegen(
    path: str | os.PathLike[str],
    *,
    raw_limits: RawLimits = DEFAULT_RAW_LIMITS,
    rate_millihz: int | None = None,
    schedule: str = "step",
) -> LoadedModel:
    """Validate (``load_checkpoint``), re-derive for ``rate_millihz`` when given (codegen/rate.py),
    parse and quantise (a raw input clamped at the limit of the channel's unit, ``raw_limits`` or
    its default: codegen/input_limits.py); every failure is a one-line UserError."""
    p = Path(path)
    raw = load_checkpoint(p)
    sha256 = hashlib.sha256(p.read_bytes()).hexdigest()

    def parsed(checkpoint: dict[str, Any]) -> tuple[Checkpoint, QuantModel]:
        ckpt = parse_checkpoint(checkpoint, str(p))
        try:
            clamp = signal_lsb(ckpt.unit, raw_limits)
            return ckpt, quantise_checkpoint(ckpt, signal_lsb=clamp, schedule=schedule)
        except UserError as exc:
            raise UserError(f"{p}: {exc}") from None

    retimed, rate_note = retime_checkpoint(raw, rate_millihz, str(p))
    ckpt, quantised = parsed(retimed)
    if (
        rate_millihz is not None
        and rate_note is not None
        and declared_rate_millihz(quantised) == ANY_RATE_MILLIHZ
    ):
        # nothing in it was built for the rate after all: exported as trained, as a memoryless model is
        ckpt, quantised = parsed(raw)
        rate_note = any_rate_note(raw, rate_millihz)
    notes = offset_notes(p, raw) + ((rate_note,) if rate_note else ()) + undetermined_notes(raw)
    from trainer.selection import shown_name

    shown = shown_name(ckpt.method, TrainStats.of_checkpoint(raw))
    return LoadedModel(p, sha256, ckpt, quantised, channel_notes(raw, notes), shown, sensor_of(raw))


UNDETERMINED_WARNING = "WARNING: the model carries what its training run does not determine"


def undetermined_notes(raw: dict[str, Any]) -> tuple[str, ...]:
    """A warning, printed and in ``NAME.h``, when the model carries parameters its training run does
    not determine (``Compensator.undetermined``: a forced physics structure); ``trainer report`` asks
    for a review of such a model."""
    from trainer import methods

    # the family's parser has read the payload (a physics one through from_payload, which checks it)
    lines = methods.REGISTRY[raw["method"]].cls.undetermined_in(raw["payload"])
    if not lines:
        return ()
    return (
        f"{UNDETERMINED_WARNING} ({'; '.join(lines)}): it "
        "extrapolates wherever its state is not the training run's (trainer report asks for a review)",
    )


def channel_notes(raw: dict[str, Any], notes: tuple[str, ...]) -> tuple[str, ...]:
    """A gyroscope or barometer channel's model (trainer fit --channels): its unit in every note and
    a first note naming the channel, its unit and LSB (every figure of the header is in that unit)."""
    from trainer.data.channels import UNIT_LABELS, relabel_units

    stats = TrainStats.of_checkpoint(raw)
    unit = stats.unit
    if unit is None or unit not in UNIT_LABELS or unit == "mg":
        return notes
    label = UNIT_LABELS[unit]
    first = f"channel {stats.channel}: values in {label}, one LSB {STEP_UNITS[unit].short}"
    relabelled = (
        relabel_units(note, unit).replace("accelerometer calibration", "sensor calibration") for note in notes
    )
    return (first, *relabelled)


def offset_notes(path: Path, raw: dict[str, Any]) -> tuple[str, ...]:
    """The constant the module removes (trainer/reference.py), or the recursive-method warning.

    ``trainer fit`` refuses a constant above the limit; a file without an offset record (written
    before the policy existed, or by hand) removes its fitted constant: it is measured at the
    mid-point of the valid range and reported, with a warning above the limit.
    """
    method = registry.REGISTRY[raw["method"]]
    if removes_sustained_input(method):
        stats = raw.get("train_stats")
        unit = stats.get("unit") if isinstance(stats, dict) else None
        return (recursive_note(unit if isinstance(unit, str) else "mg"),)
    if "offset" in raw:
        try:
            record = OffsetRecord.from_dict(raw["offset"])
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"{path}: field 'offset' is malformed ({exc})") from None
        check_constant(record, str(path))
        return (record.describe(),)
    try:
        model, _ = load_model(path)
    except UserError:  # a layout the generator reads but the trainer does not (hand-made files)
        return (f"offset: not recorded in {path.name} and not measurable by the trainer; check it",)
    lo, hi = (float(v) for v in raw["valid_temp_range_c"])
    frontend = raw["payload"].get("frontend", {}) if isinstance(raw["payload"], dict) else {}
    rate_hz = float(frontend.get("rate_hz", TrainStats.of_checkpoint(raw).sample_rate_hz or 1.0))
    t_ref = 0.5 * (lo + hi)
    constant = model.drift_at_reference(t_ref, rate_hz)
    note = (
        f"offset: not recorded in {path.name} (fitted before the offset policy): it removes its fitted "
        f"constant, {constant:.4g} mg at T_ref {t_ref:.2f} degC"
    )
    if abs(constant) > OFFSET_LIMIT_MG:
        note += (
            f"; WARNING: above {OFFSET_LIMIT_MG:g} mg, gravity or a static offset: refit with "
            f"'trainer fit' ({OFFSET_OPTION} relative, the default)"
        )
    return (note,)


def sensor_of(raw: dict[str, Any]) -> str:
    """What the header's title names: "accelerometer", or the channel's sensor and name
    ("gyroscope (channel gyro0_y, deg/s)") for a model of a gyroscope or barometer channel."""
    from trainer.data.channels import SENSOR_NAMES, UNIT_LABELS

    stats = TrainStats.of_checkpoint(raw)
    if stats.unit is None or stats.unit not in SENSOR_NAMES or stats.unit == "mg":
        return SENSOR_NAMES["mg"]
    return f"{SENSOR_NAMES[stats.unit]} (channel {stats.channel}, {UNIT_LABELS[stats.unit]})"


def manifest_name(name: str) -> str:
    return f"{name}.manifest.json"


def generate(model: LoadedModel, name: str) -> dict[str, str]:
    """File name -> content of the three output files (pure; nothing touches the disk)."""
    name = validate_name(name)
    files = render_sources(
        model.quantised,
        name,
        model.sha256,
        notes=model.notes,
        sensor=model.sensor,
        shown=model.name,
    )
    manifest = build_manifest(
        model.quantised,
        name=name,
        sha256=model.sha256,
        valid_temp_range_c=model.checkpoint.valid_temp_range_c,
    )
    if model.notes and model.sensor != sensor_of({}):  # a channel's: the first note says how the units read
        units = manifest["units"]
        assert isinstance(units, dict)
        manifest["units"] = {**units, "channel": f"{model.sensor}: {model.notes[0]}"}
    files[manifest_name(name)] = manifest_json(manifest)
    return files


BLOB_SUFFIX = ".cal.bin"  # an IMU module's calibration blob (codegen/imu.py)


def module_files(name: str) -> tuple[str, ...]:
    """Every file name a C export of module ``name`` can write (NAME.h, NAME.c, its manifest; its blob
    with --blob): what an earlier export of NAME into the same folder may have left and this one
    replaces (its kernel headers are shared by the modules of a folder and are not its own)."""
    return (f"{name}.h", f"{name}.c", manifest_name(name), f"{name}{BLOB_SUFFIX}")


def write_files_atomically(
    files: Mapping[str, str | bytes],
    out_dir: str | os.PathLike[str],
    *,
    owned: Collection[str] = (),
) -> list[str]:
    """Write ``files`` into ``out_dir`` (created if absent, parent must exist) as one set: a reader
    (or a kill) sees the old files or the new ones, never a mix (trainer/atomic_dir.py).

    ``owned`` names the files the export owns (:func:`module_files`): those of them in ``out_dir``
    that ``files`` does not hold were written by an earlier export of the same module and are removed
    in the same replacement (a blob left beside a module that does not read it would be flashed with
    it, and its module would accept it: the module id is the layout's); one ``note:`` line says so.
    Other files of ``out_dir`` are kept. Returns the names removed."""
    folder = Path(out_dir)
    stale = sorted(n for n in set(owned) - set(files) if folder.is_dir() and (folder / n).is_file())
    with atomic_directory(out_dir, drop=stale) as staging:
        for file_name, text in files.items():
            if isinstance(text, bytes):  # a calibration blob (codegen/imu.py)
                (staging / file_name).write_bytes(text)
            else:
                (staging / file_name).write_text(text, encoding="utf-8", newline="\n")
            os.chmod(staging / file_name, 0o644)
    if stale:
        why = (
            " (left beside the module, it would be flashed and loaded: the module id is the layout's, not "
            "the calibration's)"
            if any(n.endswith(BLOB_SUFFIX) for n in stale)
            else ""
        )
        print(
            f"note: {out_dir}: removed {', '.join(stale)}, which an earlier export wrote and this one does "
            f"not{why}",
            file=sys.stderr,
        )
    return stale


def export(
    model_path: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    name: str | None = None,
    raw_limits: RawLimits = DEFAULT_RAW_LIMITS,
    rate_millihz: int | None = None,
    schedule: str = "step",
) -> tuple[LoadedModel, dict[str, str]]:
    """Load, quantise (for ``rate_millihz`` when given), render and write; returns the model and files.
    ``raw_limits`` (the options given, codegen/input_limits.py; the others at their defaults) applies
    to a module that clamps its raw input of that unit; given for another, it is refused rather than
    written into a manifest it does not govern."""
    if name is not None:
        validate_name(name)
    check_raw_limits(raw_limits)
    model = load_for_codegen(model_path, raw_limits=raw_limits, rate_millihz=rate_millihz, schedule=schedule)
    clamps = family_of(model.quantised).input_clamps(model.quantised).signal_lsb is not None
    check_governed(raw_limits, [RawClamp(str(model_path), model.unit, model.name, clamps)], module=False)
    module = name or default_name(model.checkpoint.method)
    files = generate(model, module)
    write_files_atomically(files, out_dir, owned=module_files(module))
    return model, files
