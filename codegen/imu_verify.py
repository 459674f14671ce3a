"""``codegen verify`` of an IMU module: every channel, every sample, against its golden model.

The recording's channels (``trainer.data.channels``) become the module's int32 inputs; the C
runs them on the host (cffi, strict warnings) with the built-in tables and, when a calibration
blob is there, with the tables the module decoded from it; optionally on a Cortex-M4 under QEMU
(``firmware_c/Makefile`` target ``imu-app``). Outputs, per-channel flags and the sample counter
must equal the golden model of each channel's own checkpoint (:func:`codegen.imu.imu_golden`).
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cffi
import numpy as np

from codegen import cortex_m as cm
from codegen.export import BLOB_SUFFIX
from codegen.hostbuild import cdef_from_header, compile_c
from codegen.imu import MANIFEST_FORMAT, ImuModel, imu_golden, load_imu
from codegen.input_limits import raw_limits_of_clamps
from codegen.render import _environment
from codegen.verify import manifest_raw_clamp, to_step_units
from trainer.data.channels import UNIT_LABELS, channel_view, recording_channels
from trainer.data.recording import Recording
from trainer.errors import UserError, atomic_output


@dataclass
class ImuRun:
    """One run of the module (a target and a calibration source) compared with the golden model."""

    target: str  # host | cortex-m4
    calibration: str  # builtin | blob
    mismatches: list[int]  # per channel
    state_equal: bool
    instructions_per_step: float | None = None  # cortex-m4: all channels, call included


@dataclass
class ImuVerifyResult:
    name: str
    samples: int
    channels: list[str]
    units: list[str]
    runs: list[ImuRun] = field(default_factory=list)
    model_ids: list[str] = field(default_factory=list)  # per channel: "sha256:" of its model.pt
    rate_millihz: int = 0  # the module's rate contract (0: memoryless, any rate)

    @property
    def ok(self) -> bool:
        return all(sum(run.mismatches) == 0 and run.state_equal for run in self.runs)

    def channel_mismatches(self, index: int) -> int:
        """Mismatches of one channel over every run (targets and calibration sources)."""
        return sum(run.mismatches[index] for run in self.runs)


# codegen verify --channels --json writes it; trainer report --verify reads it
IMU_VERIFY_FORMAT = "mems-tdc-imu-verify"


def imu_verify_json(result: ImuVerifyResult) -> dict[str, Any]:
    """The result as plain JSON data: per channel (name, unit, model id, mismatches) and per run, so
    that ``trainer report --verify F.json`` can sign off any channel of the module."""
    return {
        "format": IMU_VERIFY_FORMAT,
        "name": result.name,
        "samples": result.samples,
        "mismatches": sum(sum(run.mismatches) for run in result.runs),
        "state_equal": all(run.state_equal for run in result.runs),
        "rate_millihz": result.rate_millihz,
        "channels": [
            # the unit as the module's manifest spells it (deg/s), not the column suffix (dps)
            {
                "name": name,
                "unit": UNIT_LABELS[unit],
                "model_id": model_id,
                "mismatches": result.channel_mismatches(k),
            }
            for k, (name, unit, model_id) in enumerate(
                zip(result.channels, result.units, result.model_ids, strict=True)
            )
        ],
        "runs": [
            {
                "target": run.target,
                "calibration": run.calibration,
                "mismatches": run.mismatches,
                "state_equal": run.state_equal,
                "instructions_per_step": run.instructions_per_step,
            }
            for run in result.runs
        ],
    }


def write_imu_json(result: ImuVerifyResult, path: str | Path) -> None:
    """``codegen verify --channels ... --json PATH``, written atomically."""
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(imu_verify_json(result), indent=2, sort_keys=True) + "\n", encoding="utf-8")


def imu_manifest(out_dir: Path, name: str | None) -> tuple[str, dict[str, Any]] | None:
    """(NAME, manifest) when ``out_dir`` holds an IMU module (of ``name`` if given), else None."""
    for path in sorted(out_dir.glob("*.manifest.json")):
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if data.get("format") == MANIFEST_FORMAT and (name is None or data.get("name") == name):
            return str(data["name"]), data
    return None


def manifest_raw_limits(manifest: dict[str, Any], path: Path) -> dict[str, float]:
    """The raw-input limits the module was exported with (unit -> ``--accel-limit-g``,
    ``--gyro-limit-dps``): where its channels that clamp their raw input (a recursive DLSTM's) clamp
    it, from each channel's ``input_limits`` (manifest format 2), one limit per unit (channels of
    one unit at different limits are refused); a unit none of whose channels clamps takes its default
    (which then changes nothing), as every unit of a manifest without ``input_limits``."""

    def clamps_raw(channel: Any) -> bool:
        limits = channel.get("input_limits") if isinstance(channel, dict) else None
        signal = limits.get("input") if isinstance(limits, dict) else None
        return isinstance(signal, dict) and signal.get("clamped") is True

    clamps = [manifest_raw_clamp(c, path) for c in manifest.get("channels", []) if clamps_raw(c)]
    return raw_limits_of_clamps([c for c in clamps if c is not None], str(path))


def step_inputs(imu: ImuModel, rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """(raw [n, channels], temp [n, sensors]) int32 from a multi-channel recording."""
    available = recording_channels(rec)
    missing = [c.name for c in imu.channels if c.name not in available]
    if missing:
        raise UserError(
            f"{rec.source}: the module's channel {missing[0]} is not in this recording; available: "
            f"{', '.join(available) or '(none)'}"
        )
    raw = np.empty((len(rec), len(imu.channels)), dtype=np.int32)
    temp = np.empty((len(rec), len(imu.sensors)), dtype=np.int32)
    for k, channel in enumerate(imu.channels):
        values, temps = to_step_units(channel_view(rec, available[channel.name]))
        raw[:, k] = values
        temp[:, imu.sensors.index(channel.sensor)] = temps
    return raw, temp


def host_run(
    out_dir: Path, name: str, raw: np.ndarray, temp: np.ndarray, blob: bytes | None, cc: str | None
) -> tuple[np.ndarray, list[int], int]:
    header = (out_dir / f"{name}.h").read_text()
    ffi = cffi.FFI()
    ffi.cdef(cdef_from_header(header))
    ffi.cdef(f"void {name}host_run({name}_state_t *, const int32_t *, const int32_t *, int32_t *, size_t);")
    with tempfile.TemporaryDirectory(prefix="imu-host-") as tmp:
        loop = Path(tmp) / f"{name}host_run.c"
        channels, sensors = raw.shape[1], temp.shape[1]
        loop.write_text(
            f'#include "{name}.h"\n'
            f"void {name}host_run({name}_state_t *s, const int32_t *raw, const int32_t *temp, int32_t *out,"
            f" size_t n);\n"
            f"void {name}host_run({name}_state_t *s, const int32_t *raw, const int32_t *temp, int32_t *out,"
            f" size_t n)\n{{\n    size_t k;\n    for (k = 0u; k < n; ++k) {{\n"
            f"        {name}_step(s, raw + k * {channels}u, temp + k * {sensors}u, out + k * {channels}u);\n"
            f"    }}\n}}\n"
        )
        library = Path(tmp) / "libimu.so"
        compile_c([out_dir / f"{name}.c", loop], library, include_dirs=[out_dir], cc=cc, shared=True)
        lib = ffi.dlopen(str(library))
    state = ffi.new(f"{name}_state_t *")
    if blob is None:
        cal = getattr(lib, f"{name}_builtin")()
    else:
        cal = ffi.new(f"{name}_calibration_t *")
        status = getattr(lib, f"{name}_load")(cal, ffi.from_buffer("uint8_t[]", blob), len(blob))
        if status != 0:
            raise UserError(f"{out_dir / name}.c refuses the calibration blob (status {status})")
    getattr(lib, f"{name}_init")(state, cal)
    raw_c = np.ascontiguousarray(raw, dtype=np.int32)
    temp_c = np.ascontiguousarray(temp, dtype=np.int32)
    out = np.empty_like(raw_c)
    getattr(lib, f"{name}host_run")(
        state,
        ffi.from_buffer("int32_t[]", raw_c),
        ffi.from_buffer("int32_t[]", temp_c),
        ffi.from_buffer("int32_t[]", out),
        raw_c.shape[0],
    )
    return out, [int(v) for v in state.flags], int(state.samples)


def load_host_module(
    out_dir: Path, name: str, cc: str | None = None, flags: tuple[str, ...] = ("-O2",)
) -> tuple[cffi.FFI, Any]:
    """The module as a host library (for tests of ``NAME_load``)."""
    ffi = cffi.FFI()
    ffi.cdef(cdef_from_header((out_dir / f"{name}.h").read_text()))
    with tempfile.TemporaryDirectory(prefix="imu-host-") as tmp:
        library = Path(tmp) / "libimu.so"
        compile_c([out_dir / f"{name}.c"], library, include_dirs=[out_dir], cc=cc, flags=flags, shared=True)
        lib = ffi.dlopen(str(library))
    return ffi, lib


def target_run(
    out_dir: Path,
    name: str,
    imu: ImuModel,
    raw: np.ndarray,
    temp: np.ndarray,
    blob: bytes | None,
    work: Path,
    builtin: bool,
) -> tuple[np.ndarray, list[int], int, float]:
    """The module on a Cortex-M4 (QEMU mps2-an386), built by firmware_c/Makefile's imu-app target;
    also the instructions per step call (SysTick under ``-icount shift=0``, the loop subtracted)."""
    reason = cm.ensure_toolchain()
    if reason is not None:
        raise UserError(f"--cortex-m4: {reason}")
    work.mkdir(parents=True, exist_ok=True)
    app = work / f"{name}_app.c"
    app.write_text(
        _environment()
        .get_template("harness_imu.c.j2")
        .render(
            name=name,
            NAME=name.upper(),
            n_channels=len(imu.channels),
            n_sensors=len(imu.sensors),
            builtin=builtin,
            blob_capacity=max(len(blob) if blob else 0, 64),
        )
    )
    build = cm.Build(out_dir, name, work / "build")
    try:
        build.make("imu-app", IMU_APP=str(app.resolve()))
    except cm.FirmwareError as exc:
        raise UserError(f"--cortex-m4: {str(exc).splitlines()[0]}") from None
    records = np.concatenate([raw, temp], axis=1).astype("<i4")
    (work / "vectors.bin").write_bytes(records.tobytes())
    args = ["vectors.bin", "outputs.bin", "state.bin"]
    if blob is not None:
        (work / "blob.bin").write_bytes(blob)
        args.append("blob.bin")
    stdout = cm.run_qemu(build.elf("imu_app"), args, cwd=work, icount=True)
    out = np.fromfile(work / "outputs.bin", dtype="<i4").reshape(raw.shape)
    state = np.fromfile(work / "state.bin", dtype="<u4")
    ticks = next(line.split()[1:] for line in stdout.splitlines() if line.startswith("ticks "))
    per_tick = 1e9 / cm.SYSCLK_HZ  # -icount shift=0: 1 ns per instruction
    instructions = (int(ticks[0]) - int(ticks[1])) * per_tick / max(len(raw), 1)
    return out, [int(v) for v in state[:-1]], int(state[-1]), instructions


def verify_imu(
    models: list[Path],
    out_dir: Path,
    rec: Recording,
    *,
    name: str | None = None,
    cc: str | None = None,
    cortex_m4: bool = False,
) -> ImuVerifyResult:
    found = imu_manifest(out_dir, name)
    if found is None:
        raise UserError(f"{out_dir}: no IMU module (NAME.manifest.json of 'codegen export --channels')")
    name, manifest = found
    rates = manifest.get("rates")
    declared = rates.get("sample_rate_millihz") if isinstance(rates, dict) else None
    module_rate = declared if isinstance(declared, int) and declared > 0 else None
    raw_limits = manifest_raw_limits(manifest, out_dir / f"{name}.manifest.json")
    # physics filters, DLSTM windows (--rate) and raw-input clamps (--accel-limit-g, --gyro-limit-dps)
    # as exported
    imu = load_imu(models, rate_millihz=module_rate, raw_limits=raw_limits)
    module_channels = [c["name"] for c in manifest["channels"]]
    if [c.name for c in imu.channels] != module_channels:
        raise UserError(
            f"{out_dir / name}.c holds the channels {', '.join(module_channels)}; verify it with --channels all "
            f"or that list (models given: {', '.join(c.name for c in imu.channels)})"
        )
    if manifest["calibration"]["sha256"] != imu.sha256 and manifest["calibration"]["builtin"]:
        raise UserError(f"{out_dir / name}.c was generated from other models (calibration sha256 differs)")
    rate_hz = imu.rate_millihz / 1000
    if rate_hz and abs(rec.sample_rate_hz - rate_hz) > 0.01 * rate_hz:
        timed = next(f.timed for f in imu.forms() if f.timed and imu.of_form(f))
        raise UserError(
            f"{rec.source}: sample rate {rec.sample_rate_hz:g} Hz, the {timed} are for "
            f"{rate_hz:g} Hz (export the module with --rate {rec.sample_rate_hz:g})"
        )
    raw, temp = step_inputs(imu, rec)
    g_out, g_flags, g_samples = imu_golden(imu, raw, temp)
    result = ImuVerifyResult(
        name,
        len(rec),
        [c.name for c in imu.channels],
        [c.unit for c in imu.channels],
        model_ids=[f"sha256:{c.model.sha256}" for c in imu.channels],
        rate_millihz=imu.rate_millihz,
    )
    sources: list[tuple[str, bytes | None]] = []
    if manifest["calibration"]["builtin"]:
        sources.append(("builtin", None))
    blob_path = out_dir / f"{name}{BLOB_SUFFIX}"
    if blob_path.is_file():
        data = blob_path.read_bytes()
        if data[16:48] != bytes.fromhex(imu.sha256):
            raise UserError(
                f"{blob_path}: the calibration of other models (its sha256 is not the given models')"
            )
        sources.append(("blob", data))
    if not sources:
        raise UserError(f"{out_dir}: a data-only module and no {blob_path.name} beside it")
    builtin = bool(manifest["calibration"]["builtin"])

    def record(
        target: str, calibration: str, run: tuple[np.ndarray, list[int], int], cost: float | None = None
    ) -> None:
        out, flags, samples = run
        mismatches = [
            int(np.count_nonzero(out[:, k].astype(np.int64) != g_out[:, k])) for k in range(out.shape[1])
        ]
        result.runs.append(
            ImuRun(target, calibration, mismatches, flags == g_flags and samples == g_samples, cost)
        )

    for calibration, blob in sources:
        record("host", calibration, host_run(out_dir, name, raw, temp, blob, cc))
        if cortex_m4:
            with tempfile.TemporaryDirectory(prefix="imu-qemu-") as work:
                out, flags, samples, cost = target_run(
                    out_dir, name, imu, raw, temp, blob, Path(work), builtin
                )
            record("cortex-m4", calibration, (out, flags, samples), cost)
    return result


def imu_report_lines(result: ImuVerifyResult) -> list[str]:
    lines = [
        f"{result.name}: {len(result.channels)} channel{'' if len(result.channels) == 1 else 's'} x "
        f"{result.samples} samples against each channel's golden model"
    ]
    for run in result.runs:
        per = ", ".join(f"{c} {m}" for c, m in zip(result.channels, run.mismatches, strict=True))
        lines.append(
            f"  {run.target} ({run.calibration} calibration): {sum(run.mismatches)} mismatches ({per}); "
            f"flags and sample counter {'equal' if run.state_equal else 'DIFFER'}"
            + (
                f"; {run.instructions_per_step:.0f} instructions per step"
                if run.instructions_per_step
                else ""
            )
        )
    return lines
