"""One C module for a whole IMU: every channel's model behind one state and one step call.

``codegen export DIR --channels all`` (DIR written by ``trainer fit --channels``) renders
``NAME.h``/``NAME.c`` from ``templates/imu.{h,c}.j2``. The module is table driven: the per-channel
tables (a cubic's coefficients, a piecewise-linear model's splits, slopes and intercepts) sit in
a ``NAME_calibration_t`` that is either compiled in (``NAME_builtin()``) or decoded at init from a
*calibration blob* (``NAME_load``), a documented little-endian byte layout with a layout version,
the module id and a CRC32 (docs/imu-module.md), so a factory flashes per-unit calibration without
recompiling. The arithmetic is the kernel library's (``tdc_kernels.h``, included as is) in exactly
the order of the one-channel templates, so each channel is bit-exact against the golden model of
its own checkpoint (:func:`imu_golden`). Methods: poly3, pla and physics (the grey-box model: its
filter and branch state per channel in the one state struct, its step the one-channel physics
module's, rendered from the same template macro, ``_physics_step.c.j2``), and the DLSTMs: a DLSTM
channel keeps the one-channel module of its checkpoint, named ``NAME_<channel>`` and embedded
verbatim in ``NAME.h``/``NAME.c`` (one translation unit still), its state a member of the
caller-owned ``NAME_state_t``; it has no calibration-blob record.

Channel units: raw and compensated values are int32 in 1/16000 of the channel's unit (mg -> the
one-channel modules' 1/16 ug; deg/s; Pa), so the one-channel quantiser applies unchanged.
"""

from __future__ import annotations

import hashlib
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from codegen import __version__
from codegen.export import LoadedModel, load_for_codegen
from codegen.families.physics.quantise import QLowpass, QPhysics
from codegen.families.physics.render import KERNEL_FILE as PHYSICS_KERNEL_FILE
from codegen.families.physics.render import KERNEL_PATH as PHYSICS_KERNEL_HEADER
from codegen.families.physics.render import physics_snippets
from codegen.family import QuantModel, family_of
from codegen.golden_select import golden_for
from codegen.imu_record import KIND_CUBIC, KIND_PHYSICS, KIND_PLA, KIND_STREAM, ChannelTables
from codegen.quantize import DEFAULT_ACCEL_LIMIT_G, TEMP_LIMITS_MDEGC
from codegen.rate import declared_rate_millihz
from codegen.render import (
    FLAGS,
    KERNEL_FILE,
    _environment,
    header_version,
    kernel_header,
    manifest_json,
    render_sources,
    validate_name,
)
from trainer.data.channels import UNIT_LABELS, sort_key
from trainer.data.flightlog import parse_channel
from trainer.errors import UserError
from trainer.physics.catalogue.streamed import c_options, c_terms
from trainer.physics.catalogue.streaming import FixedPoint
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
LSB_PER_UNIT = 16000  # 1/16000 of mg, deg/s or Pa (for mg: the one-channel modules' 1/16 ug)
MANIFEST_FORMAT = "mems-tdc-imu-module"
BLOB_SUFFIX = ".cal.bin"


@dataclass(frozen=True)
class ImuChannel:
    """One channel of the module: name (accel0_x), unit suffix, temperature input, loaded model."""

    name: str
    unit: str
    sensor: str  # accel0, gyro0, baro0: the temperature input it reads
    model: LoadedModel

    @property
    def kind(self) -> int:
        form = family_of(self.model.quantised).imu
        assert form is not None  # load_imu refuses the others
        return form.kind


@dataclass(frozen=True)
class ImuModel:
    channels: tuple[ImuChannel, ...]
    sensors: tuple[str, ...]
    valid_mdegc: tuple[tuple[int, int], ...]  # per sensor
    max_intervals: int  # capacity of a piecewise-linear channel's tables (>= 1)
    rate_millihz: int  # the physics channels' sample rate (one step call for all); 0: memoryless, any

    @property
    def physics(self) -> tuple[ImuChannel, ...]:
        """The physics channels, in slot order (their tables and state are NAME_physics[slot])."""
        return tuple(c for c in self.channels if c.kind == KIND_PHYSICS)

    @property
    def streams(self) -> tuple[ImuChannel, ...]:
        """The DLSTM channels (each runs its own one-channel module, its state in state->stream)."""
        return tuple(c for c in self.channels if c.kind == KIND_STREAM)

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
        if self.physics:  # the state holds their filters: a blob must put them on the same channels
            text += f";P={','.join(c.name for c in self.physics)};R={self.rate_millihz}"
        if self.streams:
            text += f";D={','.join(c.name for c in self.streams)};R={self.rate_millihz}"
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
    paths: list[Path], *, accel_limit_g: float = DEFAULT_ACCEL_LIMIT_G, rate_millihz: int | None = None
) -> ImuModel:
    """Load the channels' models (physics ones re-derived for ``rate_millihz`` when given); refuse
    what one table-driven module cannot hold."""
    from trainer.checkpoint import load_checkpoint

    channels = []
    for path in paths:
        name = _channel_of(load_checkpoint(path), path)
        model = load_for_codegen(path, accel_limit_g=accel_limit_g, rate_millihz=rate_millihz)
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
        raise UserError(f"channel {duplicate} is given twice")
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
        raise UserError(
            f"the timed channels (physics, DLSTM) are for different sample rates ({', '.join(f'{r / 1000:g} Hz' for r in sorted(rates))}); "
            f"one step call runs them all: export with --rate HZ"
        )
    return ImuModel(tuple(channels), sensors, tuple(valid), capacity, rates.pop() if rates else 0)


# ------------------------------------------------------------------------------ tables and blob


def phys_terms() -> dict[str, int]:
    """A physics channel's terms, bits of NAME_physics_t.terms (the header defines them from these): one
    per C term of the streamed effects' registry, then its options, in step order."""
    names = [t.name.upper() for t in c_terms()] + c_options()
    return {name: 1 << k for k, name in enumerate(names)}


@dataclass(frozen=True)
class PhysicsTables:
    """A physics channel's constants exactly as ``NAME_physics_t`` holds them (its clip range, frac
    and cubic are in the channel's record: ``ChannelTables``), in the registry's layout
    (:func:`trainer.physics.catalogue.streamed.c_terms`; zeros for a term the channel lacks)."""

    terms: int  # phys_terms() bits
    centre: int  # mdegC
    scale: int  # 2^tf
    u_scale: int  # 2^u_shift
    filters: list[tuple[int, int, int, int]]  # per filter: c, b0, step_scale 2^(tf - s), s
    margins: list[int]  # per margin (the play's half width), Q(tf) mdegC
    gains: list[int]


def physics_tables(q: QPhysics) -> PhysicsTables:
    def lowpass(f: QLowpass | None) -> tuple[int, int, int, int]:
        return (0, 0, 0, 0) if f is None else (f.c_q, f.b_q, 1 << (q.temp_frac - f.shift), f.shift)

    present = {t.fixed.name: t for t in q.terms}
    bits = phys_terms()
    layout = c_terms()
    return PhysicsTables(
        sum(bits[name.upper()] for name in present) + sum(bits[o] for o in q.options),
        q.centre_mdegc,
        1 << q.temp_frac,
        1 << q.u_shift,
        [lowpass(present[f.name].filter if f.name in present else None) for f in layout if f.tau_s],
        [(present[f.name].margin_q or 0) if f.name in present else 0 for f in layout if f.margin],
        [
            present[f.name].gain.q if f.name in present and present[f.name].gain else 0  # type: ignore[union-attr]
            for f in layout
            if f.gain_mg_per_c
        ],
    )


def physics_layout(name: str) -> dict[str, object]:
    """What the IMU templates render of the registry's C terms: the tables' and the state's fields
    and each term's step, reading its constants from ``ph`` and testing its bit at run time."""
    layout = c_terms()
    on = {t: f"(ph->terms & {name.upper()}_PHYS_{t}) != 0u" for t in phys_terms()}

    def values(f: FixedPoint) -> dict[str, object]:
        filt = {k: f"ph->{f.name}.{k}" for k in ("c", "b0", "shift", "step_scale")}
        margin = f"ph->{f.margin_field}"
        return {**filt, "q": f"ph->{f.name}_q", "margin": margin, "margin_text": f"{margin} (Q(tf) mdegC)"}

    u_source = "t_pm"
    for f in reversed(layout):
        if f.poly_reads is not None and f.option is not None:
            u_source = f"({on[f.option]} ? state->{f.poly_reads} : {u_source})"
    words = list({w.name: w for f in layout for w in f.state}.values())
    return {
        "filters": [{"field": f.name, "doc": f.filter_doc} for f in layout if f.tau_s],
        "margins": [{"field": f.margin_field, "doc": f.margin_doc} for f in layout if f.margin],
        "gains": [{"field": f"{f.name}_q", "text": f.difference_text} for f in layout if f.gain_mg_per_c],
        "state": [w for w in words if w.wide] + [w for w in words if not w.wide],
        "words": words,
        "terms": [{"on": on[f.name.upper()], **physics_snippets(f, values(f))} for f in layout],
        "u_source": u_source,
    }


def _tables(q: QuantModel, sensor: int) -> ChannelTables:
    form = family_of(q).imu
    assert form is not None  # load_imu refuses the others
    tables: ChannelTables = form.tables(q, sensor)
    return tables


def channel_tables(imu: ImuModel, channel: ImuChannel) -> ChannelTables:
    """The channel's record, built by its family's unit (codegen/families/)."""
    return _tables(channel.model.quantised, imu.sensors.index(channel.sensor))


def encode_blob(imu: ImuModel) -> bytes:
    """The calibration blob (docs/imu-module.md): header, sensors, channels, CRC32 of all before it."""
    for channels, what in ((imu.physics, "a physics"), (imu.streams, "a DLSTM")):
        if channels:
            raise UserError(
                f"channel {channels[0].name}: {what} channel has no calibration-blob record yet; export "
                f"the module with built-in tables (without --blob / --format calibration-blob)"
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
        intervals = len(t.slopes) if t.kind == KIND_PLA else 0
        parts.append(
            CHANNEL_HEADER.pack(
                t.kind, t.sensor, t.frac, t.u_shift, intervals, 0, t.clip_lo, t.clip_hi, t.t_ref
            )
        )
        if t.kind == KIND_CUBIC:
            parts.append(struct.pack("<4i", *t.coefficients))
        else:
            n = len(t.slopes)
            parts.append(struct.pack(f"<{n - 1}i{n}i{n}q", *t.splits, *t.slopes, *t.intercepts))
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


def stream_module_name(name: str, channel: ImuChannel) -> str:
    """The C name of a DLSTM channel's own module inside the IMU module ``name``."""
    sub = f"{name}_{channel.name}"
    try:
        return validate_name(sub)
    except UserError as exc:
        raise UserError(
            f"--name {name}: the DLSTM channel {channel.name} is the embedded module {sub}, which is not a "
            f"valid module name ({exc}); choose a shorter --name"
        ) from None


def _stream_modules(imu: ImuModel, name: str) -> list[dict[str, object]]:
    """Each DLSTM channel's one-channel header and source (codegen/render.py, unchanged), to embed."""
    modules: list[dict[str, object]] = []
    for channel in imu.streams:
        sub = stream_module_name(name, channel)
        files = render_sources(channel.model.quantised, sub, channel.model.sha256, notes=channel.model.notes)
        own_include = f'#include "{sub}.h"\n'
        assert files[f"{sub}.c"].count(own_include) == 1
        modules.append(
            {
                "name": channel.name,
                "sub": sub,
                "index": imu.channels.index(channel),
                "header": files[f"{sub}.h"].rstrip("\n"),
                "source": files[f"{sub}.c"]
                .replace(own_include, f"/* {sub}.h: embedded in {name}.h */\n")
                .rstrip("\n"),
            }
        )
    return modules


def _context(imu: ImuModel, name: str, builtin: bool) -> dict[str, object]:
    tables = [channel_tables(imu, c) for c in imu.channels]
    max_splits = max(imu.max_intervals - 1, 1)

    def padded(values: tuple[int, ...], size: int) -> list[int]:
        return list(values) + [0] * (size - len(values))

    return {
        "name": name,
        "NAME": name.upper(),
        "p": f"{name}_",
        "guard": f"{name.upper()}_H_INCLUDED",
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
        "kind_cubic": KIND_CUBIC,
        "kind_pla": KIND_PLA,
        "kind_physics": KIND_PHYSICS,
        "kind_stream": KIND_STREAM,
        "physics_kernels_version": header_version(PHYSICS_KERNEL_HEADER)[1],
        "stream_channels": _stream_modules(imu, name),
        "phys_terms": phys_terms(),
        "phys": physics_layout(name),
        "rate_millihz": imu.rate_millihz,
        "rate_hz": f"{imu.rate_millihz / 1000:g}",
        "physics_channels": [
            {"name": c.name, "t": physics_tables(c.model.quantised)}
            for c in imu.physics
            if isinstance(c.model.quantised, QPhysics)
        ],
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
                "method": c.model.checkpoint.method,
                "sensor": c.sensor,
                "sha256": c.model.sha256,
                "valid": f"{c.model.checkpoint.valid_temp_range_c[0]:.2f} .. "
                f"{c.model.checkpoint.valid_temp_range_c[1]:.2f} degC",
                "t": t,
                "slot": imu.physics.index(c) if c.kind == KIND_PHYSICS else 0,
                "splits": padded(t.splits, max_splits),
                "slopes": padded(t.slopes, imu.max_intervals),
                "intercepts": padded(t.intercepts, imu.max_intervals),
            }
            for c, t in zip(imu.channels, tables, strict=True)
        ],
        "sha_bytes": ", ".join(f"0x{b:02x}u" for b in bytes.fromhex(imu.sha256)),
        "loader": loader_source(name),
    }


LOADER = PHYSICS_KERNEL_HEADER.with_name(
    "tdc_imu_load.c"
)  # the calibration loader: static C of the kernel library


def loader_source(name: str) -> str:
    """The loader's C for module ``name``: from its first section line on, with the module's prefix
    for the file's placeholder ``tdcimu_`` / ``TDCIMU_`` (no trailing newline: the template's line)."""
    text = LOADER.read_text(encoding="utf-8")
    body = text[text.index("/* ---- blob decoding") :].rstrip("\n")
    return body.replace("tdcimu_", f"{name}_").replace("TDCIMU_", f"{name.upper()}_")


def render_imu(imu: ImuModel, name: str, *, builtin: bool = True) -> dict[str, str]:
    """``{NAME.h, NAME.c, tdc_kernels.h, NAME.manifest.json}`` (pure)."""
    env = _environment()
    ctx = _context(imu, validate_name(name), builtin)
    files = {
        f"{name}.h": env.get_template("imu.h.j2").render(ctx),
        f"{name}.c": env.get_template("imu.c.j2").render(ctx),
        KERNEL_FILE: kernel_header(),
    }
    if imu.physics:
        files[PHYSICS_KERNEL_FILE] = PHYSICS_KERNEL_HEADER.read_text(encoding="utf-8")
    files[f"{name}.manifest.json"] = manifest_json(_manifest(imu, name, builtin))
    return files


def _manifest(imu: ImuModel, name: str, builtin: bool) -> dict[str, object]:
    return {
        "format": MANIFEST_FORMAT,
        "format_version": 1,
        "generator": f"mems-tdc codegen {__version__}",
        "name": name,
        "calibration": {"sha256": imu.sha256, "builtin": builtin},
        "module_id": f"0x{imu.module_id:08x}",
        "blob": {"layout_version": BLOB_VERSION, "max_intervals": imu.max_intervals},
        "rates": {"sample_rate_millihz": imu.rate_millihz, "memoryless": imu.rate_millihz == 0},
        **(
            {"embedded_modules": {c.name: stream_module_name(name, c) for c in imu.streams}}
            if imu.streams
            else {}
        ),
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
    accel_limit_g: float = DEFAULT_ACCEL_LIMIT_G,
    blob: bool = False,
    blob_only: bool = False,
    rate_millihz: int | None = None,
) -> tuple[ImuModel, list[str]]:
    """Write the module (built-in tables, or data-only with ``blob``) and/or the blob, all or nothing."""
    from codegen.export import write_files_atomically

    validate_name(name)
    imu = load_imu(paths, accel_limit_g=accel_limit_g, rate_millihz=rate_millihz)
    files: dict[str, str | bytes] = {} if blob_only else dict(render_imu(imu, name, builtin=not blob))
    if blob or blob_only:
        files[f"{name}{BLOB_SUFFIX}"] = encode_blob(imu)
    write_files_atomically(files, out_dir)  # all or nothing
    written = list(files)
    return imu, written
