"""Render the C module (Jinja2 templates shipped in ``codegen/templates``) and its manifest.

Everything is a pure function of the quantised model, the NAME and the model's hash: no time,
no paths, sorted JSON keys, so the same model always gives byte-identical files.
"""

from __future__ import annotations

import json
import math
import re
import textwrap
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import jinja2
import numpy as np

from codegen import __version__
from codegen.family import InputClamps, QuantModel, family_of
from codegen.family import entries as family_entries
from codegen.qformats import HEADER as KERNEL_HEADER
from codegen.qformats import header_with_block
from codegen.quantize import FLAG_INPUT_CLAMPED, FLAG_SATURATED, FLAG_TEMP_OUT_OF_RANGE
from codegen.rate import declared_rate_millihz
from codegen.step_units import LSB_PER_UNIT, STEP_UNITS, StepUnits
from trainer.errors import UserError

MAX_NAME_LENGTH = 22  # NAME + "_model_id" stays within C99's 31 significant external characters
C_KEYWORDS = frozenset(
    [
        "auto",
        "break",
        "case",
        "char",
        "const",
        "continue",
        "default",
        "do",
        "double",
        "else",
        "enum",
        "extern",
        "float",
        "for",
        "goto",
        "if",
        "inline",
        "int",
        "long",
        "register",
        "restrict",
        "return",
        "short",
        "signed",
        "sizeof",
        "static",
        "struct",
        "switch",
        "typedef",
        "union",
        "unsigned",
        "void",
        "volatile",
        "while",
        "_Bool",
        "_Complex",
        "_Imaginary",
    ]
)
_IDENTIFIER = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
FLAGS = {
    "temp_out_of_range": FLAG_TEMP_OUT_OF_RANGE,
    "input_clamped": FLAG_INPUT_CLAMPED,
    "saturated": FLAG_SATURATED,
}
_SIZES = {"int64_t": 8, "int32_t": 4, "uint32_t": 4, "int16_t": 2, "uint16_t": 2}


def default_name(method: str) -> str:
    return "tdc_" + method.replace("-", "_")


def validate_name(name: str) -> str:
    """NAME must be a C identifier that is neither a keyword nor reserved, short enough for C99."""
    if not _IDENTIFIER.match(name):
        raise UserError(f"--name {name!r}: not a valid C identifier (a letter, then letters, digits or '_')")
    if name in C_KEYWORDS:
        raise UserError(f"--name {name!r}: is a C keyword")
    if len(name) > MAX_NAME_LENGTH:
        raise UserError(f"--name {name!r}: longer than {MAX_NAME_LENGTH} characters (C99 portability)")
    if name in kernel_library_names():
        raise UserError(
            f"--name {name!r}: the name of a kernel library file the module ships with ({name}.h or {name}.c); "
            "NAME.h and NAME.c would replace it: choose another"
        )
    return name


def kernel_library_names() -> set[str]:
    """The stems of the kernel library's files (``tdc_kernels``, ...), which an export writes beside NAME.h."""
    return {p.stem for p in KERNEL_HEADER.parent.iterdir() if p.suffix in (".h", ".c")}


@dataclass(frozen=True)
class Field:
    ctype: str
    name: str
    dims: tuple[int, ...]
    doc: str

    @property
    def size(self) -> int:
        return _SIZES[self.ctype] * int(np.prod(self.dims, dtype=np.int64))


def state_fields(model: QuantModel) -> list[Field]:
    """State struct members, widest alignment first (no interior padding; the int16 vector starts
    at a multiple of 4 bytes, so the DSP path's 32-bit reads of it are aligned): the family's, the
    common ones (flags, samples) placed among them."""
    common = [
        Field("uint32_t", "flags", (), "sticky FLAG_* bits"),
        Field("uint32_t", "samples", (), "samples since init (saturating)"),
    ]
    return family_of(model).state(model, common)


def state_bytes(fields: list[Field]) -> int:
    """sizeof the struct with natural alignment (what gcc/clang give on x86-64 and ARM EABI)."""
    offset, align = 0, 1
    for field in fields:
        a = _SIZES[field.ctype]
        offset = (offset + a - 1) // a * a + field.size
        align = max(align, a)
    return (offset + align - 1) // align * align


def table_bytes(model: QuantModel) -> dict[str, int]:
    """Flash used by the const tables (code and immediates not included)."""
    return {"model_id_string": len("sha256:") + 64 + 1, **family_of(model).tables(model)}


def c_int(value: int, width: int = 32) -> str:
    value = int(value)
    if width == 64:
        return f"INT64_C({value})"
    return str(value)


def c_rows(values: np.ndarray | list[int] | tuple[int, ...], *, width: int = 32, per_line: int = 12) -> str:
    items = [c_int(int(v), width) for v in np.asarray(values, dtype=np.int64).ravel()]
    lines = [", ".join(items[k : k + per_line]) + "," for k in range(0, len(items), per_line)]
    return "\n".join("    " + line for line in lines)


def bound_text(bound: int) -> str:
    """log2 of a bound, truncated (a bound below 2**62 never prints as 2^62.00)."""
    return f"2^{math.floor(math.log2(bound) * 100) / 100:.2f}" if bound > 0 else "0"


def _range_test(model: QuantModel) -> str:
    lim = model.limits
    return f"temp_mdegc < {lim.valid_lo_mdegc} || temp_mdegc > {lim.valid_hi_mdegc}"


def clamp_text(
    clamps: InputClamps,
    step: StepUnits,
    temp_argument: str = "temp_mdegc",
    signal_argument: str | None = None,
) -> str:
    """Where this module clamps its inputs, from its declaration (NAME.h's comment of
    NAME_FLAG_INPUT_CLAMPED): "temp_mdegc to -17603 .. 73967; rate_q16k is never clamped". The
    IMU module names the arguments as its step does (``temp_mdegc[IMU0_SENSOR_GYRO0]``)."""
    signal = step.argument if signal_argument is None else signal_argument
    clamped, never = [], []
    if clamps.temp_mdegc is not None:
        lo, hi = clamps.temp_mdegc
        clamped.append(f"{temp_argument} to {lo} .. {hi}")
    else:
        never.append(temp_argument)
    if clamps.signal_lsb is not None:
        limit = clamps.signal_lsb
        clamped.append(f"{signal} to +-{limit} (+-{limit / LSB_PER_UNIT:g} {step.label})")
    else:
        never.append(signal)
    return "; ".join([*clamped, *(f"{name} is never clamped" for name in never)])


def holds_edge_beyond_range(model: QuantModel) -> bool:
    """Whether the module's output beyond its valid temperature range holds the correction of the range's
    nearest edge (``NAME_HOLDS_EDGE_BEYOND_RANGE``), from its declared clamps (``CFamily.input_clamps``):
    its step clamps the temperature into the valid range (``Limits.valid_lo_mdegc`` .. ``valid_hi_mdegc``,
    as PX4 and ArduPilot clamp to TMIN .. TMAX) and does not read the raw input beyond subtracting the
    drift from it. A temperature clamped only to a wider range (the front end's) is extrapolated beyond
    the valid range; a model whose input is the raw signal corrects by what that signal does."""
    clamps = family_of(model).input_clamps(model)
    if clamps.temp_mdegc is None or clamps.signal_lsb is not None:
        return False
    lo, hi = clamps.temp_mdegc
    return model.limits.valid_lo_mdegc <= lo <= hi <= model.limits.valid_hi_mdegc


def holds_edge_text(model: QuantModel, step: StepUnits) -> str:
    """NAME.h's comment of NAME_HOLDS_EDGE_BEYOND_RANGE: what the module does beyond its valid range, and
    the declared clamp that makes it so."""
    clamps = family_of(model).input_clamps(model)
    if clamps.signal_lsb is not None:
        why = f"{step.argument} is the model's input"
    elif clamps.temp_mdegc is None:
        why = "temp_mdegc is never clamped"
    else:
        lo, hi = clamps.temp_mdegc
        if holds_edge_beyond_range(model):
            return f"beyond the valid range the output holds the edge's correction (temp_mdegc clamped to {lo} .. {hi})"
        why = f"temp_mdegc clamped to {lo} .. {hi} only"
    return f"beyond the valid range the output is not the edge's ({why}): use another model or the raw value"


def _context(model: QuantModel, name: str, sha256: str) -> dict[str, object]:
    lim = model.limits
    ctx: dict[str, object] = {
        "name": name,
        "NAME": name.upper(),
        "p": f"{name}_",
        "guard": f"{name.upper()}_H_INCLUDED",
        "version": __version__,
        "method": model.method,
        "sha256": sha256,
        "flags": FLAGS,
        "fields": state_fields(model),
        "range_test": _range_test(model),
        "valid_range_text": f"{lim.valid_lo_mdegc / 1000:g} .. {lim.valid_hi_mdegc / 1000:g} degC",
        "step": STEP_UNITS[lim.unit],  # the channel's words: accel_q4ug, rate_q16k, pressure_q16k
    }
    # the clamps, only as declared (CFamily.input_clamps): a template that clamps what the declaration
    # does not name fails to render (StrictUndefined), so the C and the manifest cannot disagree
    clamps = family_of(model).input_clamps(model)
    if clamps.temp_mdegc is not None:
        ctx["temp_lo"], ctx["temp_hi"] = clamps.temp_mdegc
    if clamps.signal_lsb is not None:
        ctx["signal_limit"] = clamps.signal_lsb
    ctx["clamp_doc"] = clamp_text(clamps, STEP_UNITS[lim.unit])
    ctx["holds_edge"] = int(holds_edge_beyond_range(model))
    ctx["holds_edge_doc"] = holds_edge_text(model, STEP_UNITS[lim.unit])
    millihz = declared_rate_millihz(model)
    macros: list[tuple[str, object]] = [
        ("VALID_TEMP_MIN_MDEGC", lim.valid_lo_mdegc),
        ("VALID_TEMP_MAX_MDEGC", lim.valid_hi_mdegc),
        ("SAMPLE_RATE_MILLIHZ", f"{millihz}u"),
    ]
    ctx["rate_millihz"] = millihz  # 0: memoryless, any rate (codegen/rate.py)
    unit = family_of(model)
    family_ctx = unit.context(model)
    macros += cast(list[tuple[str, object]], family_ctx.pop("macros", []))  # the family's own NAME_ macros
    ctx.update(family_ctx, family_template=unit.template.name)
    # the family's own kernel headers, each included and its version checked by the module
    ctx["kernel_headers"] = kernel_header_checks(unit.kernels.values())
    ctx.setdefault("network_step_field", None)  # no network: the benchmark harness times one kind of sample
    ctx["usage_template"] = ANY_RATE_USAGE if unit.usage is None else unit.usage.name
    ctx["restore"] = unit.restore
    ctx["macros"] = macros
    return ctx


KERNEL_FILE = "tdc_kernels.h"


_VERSION_MACRO = re.compile(r"^#define (TDC\w*_VERSION) (\d+)", re.MULTILINE)


def kernel_header_checks(paths: Iterable[Path]) -> list[dict[str, object]]:
    """What a module includes and version-checks of its extra kernel headers (file, macro, version)."""
    return [
        {"file": path.name, "macro": macro, "version": version}
        for path in paths
        for macro, version in [header_version(path)]
    ]


def header_version(path: Path) -> tuple[str, int]:
    """A kernel header's version macro and number (``#define TDC..._VERSION N``, declared in the header
    only): the generated modules check it at compile time."""
    found = _VERSION_MACRO.search(path.read_text(encoding="utf-8"))
    if found is None:
        raise UserError(f"{path}: no '#define TDC..._VERSION N'")
    return found.group(1), int(found.group(2))


TEMPLATES = Path(__file__).with_name("templates")  # the shared templates; each family's are in its unit
ANY_RATE_USAGE = "_any_rate.h.j2"  # the header's paragraph of a family without its own (CFamily.usage)


def _environment() -> jinja2.Environment:
    templates = {
        path
        for unit in family_entries()
        for path in (unit.template, unit.usage, unit.imu.snippets if unit.imu else None)
        if path is not None
    }
    family_dirs = sorted({path.parent for path in templates} - {TEMPLATES})
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader([TEMPLATES, *family_dirs]),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )
    env.globals["kernels_version"] = header_version(KERNEL_HEADER)[1]
    return env


def kernel_header() -> str:
    """The kernel library as shipped (its Q-format block checked against codegen.qformats)."""
    text = KERNEL_HEADER.read_text(encoding="utf-8")
    if header_with_block(text) != text:
        raise UserError(f"{KERNEL_HEADER}: Q-format block out of date (python -m codegen.qformats --write)")
    return text


def render_sources(
    model: QuantModel,
    name: str,
    sha256: str,
    notes: tuple[str, ...],
    sensor: str,
    shown: str = "",
) -> dict[str, str]:
    """``{NAME.h: text, NAME.c: text, tdc_kernels.h: text}`` and the family's own kernel headers
    (``tdc_physics_kernels.h`` for a physics model); ``notes`` are lines for the header's comment,
    ``sensor`` what its title names, ``shown`` the name the user knows the model by (auto's choice:
    ``none``, ``poly2``, ``physics-branch``), where it differs from the registered method. The step's
    words are the channel's (``model.limits.unit``: :mod:`codegen.step_units`)."""
    env = _environment()
    ctx = _context(model, validate_name(name), sha256)
    if shown:
        ctx["method"] = shown
    ctx["notes"] = [textwrap.wrap(note, 92) for note in notes]
    ctx["sensor"] = sensor
    files = {
        f"{name}.h": env.get_template("module.h.j2").render(ctx),
        f"{name}.c": env.get_template("module.c.j2").render(ctx),
        KERNEL_FILE: kernel_header(),
    }
    for header in family_of(model).kernels.values():
        files[header.name] = header.read_text(encoding="utf-8")
    return files


def render_template(template: str, model: QuantModel, name: str, sha256: str, **extra: object) -> str:
    """Render one of the shipped auxiliary templates (the test and benchmark harnesses)."""
    ctx = _context(model, name, sha256)
    ctx.update(extra)
    return _environment().get_template(template).render(ctx)


def manifest_json(manifest: dict[str, object]) -> str:
    return json.dumps(manifest, indent=2, sort_keys=True) + "\n"
