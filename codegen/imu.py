"""One C module for a whole IMU: every channel's model behind one state and one step call.

``codegen export DIR --channels all`` (DIR written by ``trainer fit --channels``) renders
``NAME.h``/``NAME.c`` from ``templates/imu.{h,c}.j2``. The module is table driven: the per-channel
tables (a cubic's coefficients, a piecewise-linear model's splits, slopes and intercepts) sit in
a ``NAME_calibration_t`` that is either compiled in (``NAME_builtin()``) or decoded at init from a
*calibration blob* (``NAME_load``), a documented little-endian byte layout with a layout version,
the module id and a CRC32 (docs/imu-module.md), so a factory flashes per-unit calibration without
recompiling. The arithmetic is the kernel library's (``tdc_kernels.h``, included as is) in exactly
the order of the one-channel templates, so each channel is bit-exact against the golden model of
its own checkpoint (:func:`imu_golden`).

This module and its templates know no family: each C family with an IMU-module form
(``CFamily.imu``, an ``ImuForm``: poly3, pla, physics, the DLSTMs) gives its channel record, its
blob record, its template variables and its template of macros, which the IMU templates call at
their places for every form the module holds (codegen/families/<unit>/imu.py, ``_<unit>_imu.j2``).

A module with a channel whose family has ``NAME_restore`` (physics) also has ``NAME_restore(state, cal,
saved)``: a state carries ``restore_id``, a CRC32 of ``NAME_STATE_TAG`` (the CRC32 of the header's
text, :func:`with_state_tag`) and of every value of its calibration, and each family's words are
checked against the bounds its step is proved for under that calibration (the form's macros
``c_identity``, ``c_saved_ok``, ``c_restore``; docs/imu-module.md, "Save/restore").

Channel units: raw and compensated values are int32 in 1/16000 of the channel's unit (mg -> the
one-channel modules' 1/16 ug; deg/s; Pa), so the one-channel quantiser applies unchanged.
"""

from __future__ import annotations

import hashlib
import os
import struct
import textwrap
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import jinja2
import numpy as np

from codegen import __version__
from codegen.export import (
    BLOB_SUFFIX,
    UNDETERMINED_WARNING,
    LoadedModel,
    load_for_codegen,
    manifest_name,
    module_files,
)
from codegen.family import CFamily, ImuForm, QuantModel, entries, family_of
from codegen.golden_select import golden_for
from codegen.imu_record import ChannelTables, ImuPart
from codegen.input_limits import DEFAULT_RAW_LIMITS, RawClamp, RawLimits, check_governed, check_raw_limits
from codegen.manifest import input_limits
from codegen.qformats import HEADER as KERNEL_HEADER
from codegen.quantize import TEMP_LIMITS_MDEGC
from codegen.rate import declared_rate_millihz
from codegen.render import (
    FLAGS,
    KERNEL_FILE,
    _environment,
    clamp_text,
    holds_edge_beyond_range,
    kernel_header,
    kernel_header_checks,
    manifest_json,
    validate_name,
)
from codegen.step_units import LSB_PER_UNIT as STEP_LSB_PER_UNIT
from codegen.step_units import STEP_UNITS
from trainer.data.channels import UNIT_LABELS, sort_key
from trainer.data.flightlog import parse_channel
from trainer.errors import UserError
from trainer.train_stats import TrainStats

BLOB_MAGIC = b"TDCC"
BLOB_VERSION = 1
BLOB_HEADER = struct.Struct(
    "<4sHHHHI32s"
)  # magic, version, channels, sensors, max intervals, module id, sha256
CHANNEL_HEADER = struct.Struct(
    "<BBBBHHiii"
)  # kind, sensor, frac, u_shift, intervals, reserved, clip lo/hi, t_ref
SENSOR_RECORD = struct.Struct("<ii")  # valid range lo, hi (mdegC)
LSB_PER_UNIT = STEP_LSB_PER_UNIT  # 1/16000 of mg, deg/s or Pa (for mg: the one-channel modules' 1/16 ug)
MANIFEST_FORMAT = "mems-tdc-imu-module"
MANIFEST_FORMAT_VERSION = 2  # 2: each channel's input_limits


@dataclass(frozen=True)
class ImuChannel:
    """One channel of the module: name (accel0_x), unit suffix, temperature input, loaded model."""

    name: str
    unit: str
    sensor: str  # accel0, gyro0, baro0: the temperature input it reads
    model: LoadedModel

    @property
    def family(self) -> CFamily:
        return family_of(self.model.quantised)

    @property
    def form(self) -> ImuForm:
        form = self.family.imu
        assert form is not None  # load_imu refuses the others
        return form

    @property
    def kind(self) -> int:
        return self.form.kind


@dataclass(frozen=True)
class ImuModel:
    channels: tuple[ImuChannel, ...]
    sensors: tuple[str, ...]
    valid_mdegc: tuple[tuple[int, int], ...]  # per sensor
    max_intervals: int  # capacity of a piecewise-linear channel's tables (>= 1)
    rate_millihz: int  # the timed channels' sample rate (one step call for all); 0: memoryless, any

    def of_form(self, form: ImuForm) -> tuple[ImuChannel, ...]:
        """The channels of a family's form, in slot order (a slotted family's NAME_<x>[slot])."""
        return tuple(c for c in self.channels if c.form.kind == form.kind)

    def forms(self) -> list[ImuForm]:
        """The channel forms the module holds, in kind order: those of its channels and every form
        with a calibration-blob record (a blob may put it on any channel)."""
        present = {c.form.kind for c in self.channels}
        found = {
            f.imu.kind: f.imu
            for f in entries()
            if f.imu is not None and (f.imu.blob is not None or f.imu.kind in present)
        }
        return [found[kind] for kind in sorted(found)]

    def kernel_headers(self) -> list[Path]:
        """The extra kernel headers of the families it holds (CFamily.kernels), each once."""
        kinds = {form.kind for form in self.forms()}
        paths = [
            p for f in entries() if f.imu is not None and f.imu.kind in kinds for p in f.kernels.values()
        ]
        return list(dict.fromkeys(paths))

    def part(self, form: ImuForm, name: str) -> ImuPart:
        """A family's channels in the module ``name`` (what its form's hooks see)."""
        channels = self.of_form(form)
        return ImuPart(name, channels, tuple(self.channels.index(c) for c in channels))

    @property
    def sha256(self) -> str:
        """The calibration's id: sha256 over the channel names and their model files' hashes."""
        text = "\n".join(f"{c.name} {c.model.sha256}" for c in self.channels)
        return hashlib.sha256(text.encode()).hexdigest()

    @property
    def module_id(self) -> int:
        """CRC32 of the layout (channels, units, sensors, capacity): a blob must be for this layout."""
        text = ";".join(f"{c.name}:{c.unit}:{self.sensors.index(c.sensor)}" for c in self.channels)
        text += f";S={','.join(self.sensors)};I={self.max_intervals}"
        for form in self.forms():  # the state holds theirs: a blob must put them on the same channels
            channels = self.of_form(form)
            if form.layout_tag and channels:
                text += f";{form.layout_tag}={','.join(c.name for c in channels)};R={self.rate_millihz}"
        return zlib.crc32(text.encode())


def _channel_of(raw: dict[str, Any], path: Path) -> str:
    name = TrainStats.of_checkpoint(raw).channel
    if not isinstance(name, str) or parse_channel(name) is None:
        raise UserError(
            f"{path}: the model does not name its channel (fit it with 'trainer fit --channels' on a "
            f"multi-channel recording)"
        )
    return name


def load_imu(
    paths: list[Path], *, raw_limits: RawLimits = DEFAULT_RAW_LIMITS, rate_millihz: int | None = None
) -> ImuModel:
    """Load the channels' models (physics ones re-derived for ``rate_millihz`` when given; raw inputs
    clamped at the limits of their units, ``raw_limits`` or the defaults: codegen/input_limits.py);
    refuse what one table-driven module cannot hold."""
    from trainer.checkpoint import load_checkpoint

    channels = []
    for path in paths:
        name = _channel_of(load_checkpoint(path), path)
        model = load_for_codegen(path, raw_limits=raw_limits, rate_millihz=rate_millihz)
        if family_of(model.quantised).imu is None:
            raise UserError(
                f"{path}: channel {name}: method {model.checkpoint.method!r} has no IMU-module form"
            )
        parsed = parse_channel(name)
        assert parsed is not None
        channels.append(ImuChannel(name, parsed.unit, f"{parsed.sensor}{parsed.instance}", model))
    names = [c.name for c in channels]
    duplicate = next((n for n in names if names.count(n) > 1), None)
    if duplicate is not None:
        raise UserError(f"two models for channel {duplicate} ({duplicate} given twice)")
    channels.sort(key=lambda c: sort_key(c.name))
    sensors = tuple(dict.fromkeys(c.sensor for c in channels))
    valid = []
    for sensor in sensors:
        ranges = {
            (c.model.quantised.limits.valid_lo_mdegc, c.model.quantised.limits.valid_hi_mdegc)
            for c in channels
            if c.sensor == sensor
        }
        if len(ranges) > 1:
            raise UserError(
                f"sensor {sensor}: its channels have different valid temperature ranges {sorted(ranges)}; "
                f"one temperature front end per sensor needs them fitted on one recording"
            )
        valid.append(ranges.pop())
    capacity = (
        max(  # pla intervals per channel (a unit's blob must have the module's: trainer fit --intervals)
            [len(_tables(c.model.quantised, 0).slopes) for c in channels] + [1]
        )
    )
    rates = {declared_rate_millihz(c.model.quantised) for c in channels} - {0}
    if len(rates) > 1:
        timed = {c.form.kind: c.form.label for c in channels if c.form.timed}
        raise UserError(
            f"the timed channels ({', '.join(timed[k] for k in sorted(timed))}) are for different sample rates ({', '.join(f'{r / 1000:g} Hz' for r in sorted(rates))}); "
            f"one step call runs them all: export with --rate HZ"
        )
    return ImuModel(tuple(channels), sensors, tuple(valid), capacity, rates.pop() if rates else 0)


# ------------------------------------------------------------------------------ tables and blob


def _tables(q: QuantModel, sensor: int) -> ChannelTables:
    form = family_of(q).imu
    assert form is not None  # load_imu refuses the others
    tables: ChannelTables = form.tables(q, sensor)
    _check_record_clamp(q, tables)
    return tables


def _check_record_clamp(q: QuantModel, t: ChannelTables) -> None:
    """The IMU C clamps a channel's inputs where its family declares (``CFamily.input_clamps``, what
    the manifest's ``input_limits`` states): a kind whose arithmetic is in imu.c.j2 clamps the
    temperature at its record's clip range (``clip_lo``, ``clip_hi``), which must be the declared
    clamp; a record without a clip range ((0, 0): a DLSTM's) has its clamps in its embedded
    one-channel module, rendered from the same declaration. A family whose record says otherwise
    would make the C clamp where the manifest does not say: refused at generation."""
    if (t.clip_lo, t.clip_hi) == (0, 0):
        return
    declared = family_of(q).input_clamps(q)
    if declared.temp_mdegc != (t.clip_lo, t.clip_hi) or declared.signal_lsb is not None:
        raise ValueError(
            f"{q.method}: the IMU record clamps T at {t.clip_lo} .. {t.clip_hi} mdegC and never the raw "
            f"input, the family declares {declared}"
        )


def channel_input_limits(channel: ImuChannel, name: str) -> dict[str, object]:
    """A channel's ``input_limits`` in the module's manifest: where the module's C clamps the channel's
    raw input (``raw[NAME_CH_<CHANNEL>]``, int32 LSB and the channel's unit) and its sensor's
    temperature (``temp_mdegc[NAME_SENSOR_<SENSOR>]``, mdegC), each clamp setting the channel's
    ``NAME_FLAG_INPUT_CLAMPED``. The IMU C clamps as the channel's one-channel module: a cubic,
    piecewise-linear or physics channel its temperature at its record's clip range, which is the
    family's declared clamp (:func:`_check_record_clamp`), a DLSTM channel both inputs in its embedded
    one-channel module; so this is that module's ``input_limits`` (:func:`codegen.manifest.input_limits`,
    from ``CFamily.input_clamps``), the arguments named as the IMU step's. A data-only module's
    cubic and piecewise-linear channels clamp at the clip range of the blob they are given: the
    limits stated are the calibration's the module was exported with (``calibration.sha256``)."""
    limits = input_limits(channel.model.quantised)
    signal, temp = (dict(cast(dict[str, object], limits[key])) for key in ("input", "temp"))
    signal["argument"], temp["argument"] = step_arguments(channel, name)
    signal["unit"] = UNIT_LABELS[channel.unit]  # the module's unit of the channel (its LSB: 1/16000 of it)
    return {"input": signal, "temp": temp}


def step_arguments(channel: ImuChannel, name: str) -> tuple[str, str]:
    """(raw input, temperature) of a channel as the IMU step names them."""
    return (
        f"raw[{name.upper()}_CH_{channel.name.upper()}]",
        f"temp_mdegc[{name.upper()}_SENSOR_{channel.sensor.upper()}]",
    )


def header_clamps(channel: ImuChannel, name: str) -> str:
    """The channel's "clamps:" line of NAME.h: the one-channel header's text, from the same declaration
    (``CFamily.input_clamps``), with the IMU step's argument names."""
    q = channel.model.quantised
    raw, temp = step_arguments(channel, name)
    return clamp_text(family_of(q).input_clamps(q), STEP_UNITS[q.limits.unit], temp, raw)


def channel_tables(imu: ImuModel, channel: ImuChannel) -> ChannelTables:
    """The channel's record, built by its family's unit (codegen/families/)."""
    return _tables(channel.model.quantised, imu.sensors.index(channel.sensor))


def encode_blob(imu: ImuModel) -> bytes:
    """The calibration blob (docs/imu-module.md): header, sensors, channels, CRC32 of all before it."""
    for form in imu.forms():
        channels = imu.of_form(form)
        if form.blob is None and channels:
            raise UserError(
                f"channel {channels[0].name}: a {form.label} channel has no calibration-blob record "
                f"yet; export the module with built-in tables (without --blob / --format calibration-blob)"
            )
    parts = [
        BLOB_HEADER.pack(
            BLOB_MAGIC,
            BLOB_VERSION,
            len(imu.channels),
            len(imu.sensors),
            imu.max_intervals,
            imu.module_id,
            bytes.fromhex(imu.sha256),
        )
    ]
    parts += [SENSOR_RECORD.pack(lo, hi) for lo, hi in imu.valid_mdegc]
    for channel in imu.channels:
        t = channel_tables(imu, channel)
        intervals = len(t.slopes)  # a piecewise-linear channel's (the others have none)
        parts.append(
            CHANNEL_HEADER.pack(
                t.kind, t.sensor, t.frac, t.u_shift, intervals, 0, t.clip_lo, t.clip_hi, t.t_ref
            )
        )
        assert channel.form.blob is not None  # refused above
        parts.append(channel.form.blob(t))
    body = b"".join(parts)
    return body + struct.pack("<I", zlib.crc32(body))


# ------------------------------------------------------------------------------ golden model


def imu_golden(imu: ImuModel, raw: np.ndarray, temp: np.ndarray) -> tuple[np.ndarray, list[int], int]:
    """(outputs [n, channels], flags per channel, samples): each channel through the golden model of
    its own checkpoint, fed its sensor's temperature; ``raw`` is [n, channels], ``temp`` [n, sensors]."""
    outputs = np.empty(raw.shape, dtype=np.int64)
    flags = []
    samples = 0
    for k, channel in enumerate(imu.channels):
        golden = golden_for(channel.model.quantised)
        outputs[:, k] = golden.run(raw[:, k], temp[:, imu.sensors.index(channel.sensor)])
        flags.append(golden.flags)
        samples = golden.samples
    return outputs, flags, samples


# ------------------------------------------------------------------------------ rendering


def _parts(
    imu: ImuModel, name: str, env: jinja2.Environment, common: dict[str, object]
) -> list[dict[str, object]]:
    """Each channel form the module holds (kind order): its kind, code, label and ``hooks``, its
    template's macros (ImuForm.snippets) bound to the module's and its own variables."""
    parts: list[dict[str, object]] = []
    for form in imu.forms():
        hooks: object = {}  # a form without macros fills no place
        if form.snippets is not None:
            own = form.context(imu.part(form, name)) if form.context is not None else {}
            variables = {**common, **own, "kind": form.kind, "code": form.code}
            hooks = env.get_template(form.snippets.name).make_module(variables)
        parts.append({"kind": form.kind, "code": form.code, "label": form.label, "hooks": hooks})
    return parts


def _context(imu: ImuModel, name: str, builtin: bool) -> dict[str, object]:
    tables = [channel_tables(imu, c) for c in imu.channels]
    max_splits = max(imu.max_intervals - 1, 1)
    forms = imu.forms()

    def padded(values: tuple[int, ...], size: int) -> list[int]:
        return list(values) + [0] * (size - len(values))

    def slot(channel: ImuChannel) -> int:
        return imu.of_form(channel.form).index(channel) if channel.form.slots else 0

    return {
        "name": name,
        "NAME": name.upper(),
        "p": f"{name}_",
        "guard": f"{name.upper()}_H_INCLUDED",
        # what a channel's own module would say in its header (codegen export prints the same)
        "warnings": [
            textwrap.wrap(f"{c.name}: {note}", 92)
            for c in imu.channels
            for note in c.model.notes
            if note.startswith(UNDETERMINED_WARNING)
        ],
        # channels whose one-channel module has NAME_restore: the IMU module's NAME_restore keeps their state
        "restorable": [c.name for c in imu.channels if family_of(c.model.quantised).restore],
        "state_tag": STATE_TAG_UNSET,
        "version": __version__,
        "sha256": imu.sha256,
        "module_id": f"0x{imu.module_id:08x}u",
        "blob_version": BLOB_VERSION,
        "builtin": builtin,
        "n_channels": len(imu.channels),
        "n_sensors": len(imu.sensors),
        "max_intervals": imu.max_intervals,
        "max_splits": max_splits,
        "flags": FLAGS,
        "kernel_headers": kernel_header_checks(imu.kernel_headers()),
        "slotted": [{"kind": f.kind, "label": f.label} for f in forms if f.slots],
        "timed": [f.timed for f in forms if f.timed and imu.of_form(f)],
        "timed_brief": [f.timed_brief for f in forms if f.timed_brief and imu.of_form(f)],
        "rate_millihz": imu.rate_millihz,
        "rate_hz": f"{imu.rate_millihz / 1000:g}",
        "temp_lo": TEMP_LIMITS_MDEGC[0],
        "temp_hi": TEMP_LIMITS_MDEGC[1],
        "sensors": [
            {"name": s, "upper": s.upper(), "valid_lo": lo, "valid_hi": hi}
            for s, (lo, hi) in zip(imu.sensors, imu.valid_mdegc, strict=True)
        ],
        "channels": [
            {
                "name": c.name,
                "upper": c.name.upper(),
                "unit": UNIT_LABELS[c.unit],
                "method": c.model.name,  # auto's choice (none, physics-branch) as the user knows it
                "sensor": c.sensor,
                "sha256": c.model.sha256,
                "valid": f"{c.model.checkpoint.valid_temp_range_c[0]:.2f} .. "
                f"{c.model.checkpoint.valid_temp_range_c[1]:.2f} degC",
                "t": t,
                "clamps": header_clamps(c, name),
                "holds_edge": int(holds_edge_beyond_range(c.model.quantised)),
                "slot": slot(c),
                "splits": padded(t.splits, max_splits),
                "slopes": padded(t.slopes, imu.max_intervals),
                "intercepts": padded(t.intercepts, imu.max_intervals),
            }
            for c, t in zip(imu.channels, tables, strict=True)
        ],
        "sha_bytes": ", ".join(f"0x{b:02x}u" for b in bytes.fromhex(imu.sha256)),
        "loader": loader_source(name),
    }


LOADER = KERNEL_HEADER.with_name("tdc_imu_load.c")  # the calibration loader: static C of the kernel library


def loader_source(name: str) -> str:
    """The loader's C for module ``name``: from its first section line on, with the module's prefix
    for the file's placeholder ``tdcimu_`` / ``TDCIMU_`` (no trailing newline: the template's line)."""
    text = LOADER.read_text(encoding="utf-8")
    body = text[text.index("/* ---- blob decoding") :].rstrip("\n")
    return body.replace("tdcimu_", f"{name}_").replace("TDCIMU_", f"{name.upper()}_")


STATE_TAG_UNSET = "0x00000000u"  # NAME_STATE_TAG while the header's CRC32 is taken


def with_state_tag(header: str, name: str) -> str:
    """The header with ``NAME_STATE_TAG``, the CRC32 of its own text with the tag read as
    :data:`STATE_TAG_UNSET` (a module without restorable channels has no tag: unchanged). A state
    carries it (in ``restore_id``): ``NAME_restore`` continues only a state its own module made."""
    unset = f"#define {name.upper()}_STATE_TAG {STATE_TAG_UNSET}"
    if unset not in header:
        return header
    tag = f"0x{zlib.crc32(header.encode()):08x}u"
    return header.replace(unset, f"#define {name.upper()}_STATE_TAG {tag}", 1)


def render_imu(imu: ImuModel, name: str, *, builtin: bool = True) -> dict[str, str]:
    """``{NAME.h, NAME.c, tdc_kernels.h, its families' kernel headers, NAME.manifest.json}`` (pure)."""
    env = _environment()
    ctx = _context(imu, validate_name(name), builtin)
    ctx["parts"] = _parts(imu, name, env, ctx)
    files = {
        f"{name}.h": with_state_tag(env.get_template("imu.h.j2").render(ctx), name),
        f"{name}.c": env.get_template("imu.c.j2").render(ctx),
        KERNEL_FILE: kernel_header(),
    }
    for path in imu.kernel_headers():
        files[path.name] = path.read_text(encoding="utf-8")
    files[manifest_name(name)] = manifest_json(_manifest(imu, name, builtin))
    return files


def _manifest(imu: ImuModel, name: str, builtin: bool) -> dict[str, object]:
    return {
        "format": MANIFEST_FORMAT,
        "format_version": MANIFEST_FORMAT_VERSION,
        "generator": f"mems-tdc codegen {__version__}",
        "name": name,
        "calibration": {"sha256": imu.sha256, "builtin": builtin},
        "module_id": f"0x{imu.module_id:08x}",
        "blob": {"layout_version": BLOB_VERSION, "max_intervals": imu.max_intervals},
        "rates": {"sample_rate_millihz": imu.rate_millihz, "memoryless": imu.rate_millihz == 0},
        **{
            key: value
            for form in imu.forms()
            if form.manifest is not None and imu.of_form(form)
            for key, value in form.manifest(imu.part(form, name)).items()
        },
        "sensors": [
            {"name": s, "valid_temp_range_mdegc": [lo, hi]}
            for s, (lo, hi) in zip(imu.sensors, imu.valid_mdegc, strict=True)
        ],
        "channels": [
            {
                "name": c.name,
                "unit": UNIT_LABELS[c.unit],
                "lsb_per_unit": LSB_PER_UNIT,
                "method": c.model.checkpoint.method,
                "sensor": c.sensor,
                "model": {"file": c.model.path.name, "sha256": c.model.sha256},
                "input_limits": channel_input_limits(c, name),
            }
            for c in imu.channels
        ],
        "flags": dict(FLAGS),
    }


def export_imu(
    paths: list[Path],
    out_dir: str | os.PathLike[str],
    *,
    name: str,
    raw_limits: RawLimits = DEFAULT_RAW_LIMITS,
    blob: bool = False,
    blob_only: bool = False,
    rate_millihz: int | None = None,
) -> tuple[ImuModel, list[str]]:
    """Write the module (built-in tables, or data-only with ``blob``) and/or the blob, all or nothing;
    ``raw_limits`` (the options given) is refused for a unit none of whose channels clamps its raw input."""
    from codegen.export import write_files_atomically

    validate_name(name)
    check_raw_limits(raw_limits)
    imu = load_imu(paths, raw_limits=raw_limits, rate_millihz=rate_millihz)
    check_governed(
        raw_limits,
        [
            RawClamp(
                c.name, c.unit, c.model.name, c.family.input_clamps(c.model.quantised).signal_lsb is not None
            )
            for c in imu.channels
        ],
        module=True,
    )
    files: dict[str, str | bytes] = {} if blob_only else dict(render_imu(imu, name, builtin=not blob))
    if blob or blob_only:
        files[f"{name}{BLOB_SUFFIX}"] = encode_blob(imu)
    # all or nothing; a module's set replaces the earlier export's whole (a blob it does not read is
    # removed), a blob alone (the factory path) is one unit's calibration for the module beside it
    write_files_atomically(files, out_dir, owned=() if blob_only else module_files(name))
    written = list(files)
    return imu, written
