"""Render the C module (Jinja2 templates shipped in ``codegen/templates``) and its manifest.

Everything is a pure function of the quantised model, the NAME and the model's hash: no time,
no paths, sorted JSON keys, so the same model always gives byte-identical files.
"""

from __future__ import annotations

import json
import math
import re
import textwrap
from dataclasses import dataclass
from pathlib import Path
from string import Template
from typing import cast

import jinja2
import numpy as np

from codegen import __version__
from codegen.activations import ACT_KNOT, activation_errors
from codegen.family import QuantModel, family_of
from codegen.family import entries as family_entries
from codegen.qformats import (
    ACT_SEGMENTS,
    C_FRAC,
    EST_FRAC,
    header_with_block,
)
from codegen.qformats import HEADER as KERNEL_HEADER
from codegen.quantize import (
    EST_LIMIT,
    FLAG_INPUT_CLAMPED,
    FLAG_SATURATED,
    FLAG_TEMP_OUT_OF_RANGE,
    HI_BITS,
    UNIT_TASKS,
    QPhysics,
    QStream,
    QTerm,
)
from codegen.rate import declared_rate_millihz
from trainer import methods as registry
from trainer.errors import UserError
from trainer.physics.catalogue.streaming import FixedPoint, StateWord

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
    return name


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
    at a multiple of 4 bytes, so the DSP path's 32-bit reads of it are aligned)."""
    common = [
        Field("uint32_t", "flags", (), "sticky FLAG_* bits"),
        Field("uint32_t", "samples", (), "samples since init (saturating)"),
    ]
    if isinstance(model, QPhysics):
        wide = f"Q{model.temp_frac + HI_BITS} mdegC about {model.centre_mdegc} mdegC"
        narrow = f"Q{model.temp_frac} mdegC"
        words = physics_state_words(model)
        return [
            *(Field("int64_t", w.name, (), f"{w.doc}, {wide}") for w in words if w.wide),
            *(Field("int32_t", w.name, (), f"{w.doc}, {narrow}") for w in words if not w.wide),
            Field("int32_t", "temp_prev", (), "previous clipped temperature, mdegC"),
            Field("uint32_t", "started", (), "0 until the first sample after init/reset"),
            Field("uint32_t", "model_tag", (), "NAME_MODEL_TAG: a restore checks it"),
            *common,
        ]
    return family_of(model).state(model, common)


def stream_state_fields(model: QStream, common: list[Field]) -> list[Field]:
    """The stream family's state members, the common ones (flags, samples) placed among them."""
    unit = "mdegC" if model.kind == "temperature" else "1/16 ug"
    fields = [Field("int64_t", "window_current", (), f"running sum since the window's start phase, {unit}")]
    if model.chunks:
        fields.append(
            Field("int64_t", "window_ring", (model.chunks,), f"sums of the last decimation periods, {unit}")
        )
    if model.kind == "temperature":
        fields.append(
            Field("int64_t", "prev_mean", (), f"window mean at the previous step, Q{model.mean_frac} mdegC")
        )
    L, H = len(model.layers), model.hidden_size
    if L:
        fields.append(Field("int32_t", "c", (L, H), f"cell states, Q7.{C_FRAC}"))
    fields += [
        Field("int32_t", "estimate", (), "held drift estimate, 1/16 ug, whole part (floor)"),
        Field("uint32_t", "estimate_frac", (), "its fraction, 1/2^16 of 1/16 ug"),
        Field("uint32_t", "shaper", (), "output rounding: accumulated fractions, 1/2^16 of 1/16 ug"),
    ]
    if model.chunks:
        fields.append(Field("uint32_t", "ring_pos", (), "next slot of window_ring"))
    fields += [
        Field("uint32_t", "phase", (), "n mod decimation; the network steps at 0"),
        Field("uint32_t", "steps", (), "network steps since reset (saturating)"),
        *common,
    ]
    spread = L and model.schedule == "spread"
    if spread:
        fields += [
            Field("int64_t", "mean", (), f"spread schedule: the step's window mean, Q{model.mean_frac}"),
            Field("uint32_t", "task", (), "spread schedule: the step's next task"),
            Field("uint32_t", "credit", (), "spread schedule: phase x tasks mod decimation"),
            Field("uint32_t", "acc", (4,), "spread schedule: a unit's gate accumulators, excess 2^31"),
        ]
    if L:
        fields.append(
            Field(
                "int16_t",
                "vec",
                (model.vector_slots,),
                "network inputs x (Q11, a pair), then h of each layer (Q15)",
            )
        )
    if spread:
        fields.append(Field("int16_t", "h_new", (model.hidden_slots,), "spread schedule: the layer's new h"))
    return fields


def physics_state_words(model: QPhysics) -> list[StateWord]:
    """The state words a physics model keeps (its terms' filters and play operator), in step order."""
    return [w for t in model.terms for w in t.fixed.state]


def physics_snippets(fixed: FixedPoint, values: dict[str, object]) -> dict[str, str]:
    """A streamed effect's C step before and after the polynomial, its constants filled in."""
    return {
        "before": Template(fixed.before_poly).substitute(values),
        "after": Template(fixed.after_poly).substitute(values),
    }


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


def stream_tables(model: QStream) -> dict[str, int]:
    if not model.layers:
        return {}
    return {
        "activation_table": 2 * ACT_KNOT.size,
        "weights": sum(2 * lay.w_padded.size for lay in model.layers) + 4 * model.hidden_size,
        "biases": sum(4 * lay.b.size for lay in model.layers),
    }


def physics_tables(model: QPhysics) -> dict[str, int]:
    return {"physics_coefficients": 16}


def _c_int(value: int, width: int = 32) -> str:
    value = int(value)
    if width == 64:
        return f"INT64_C({value})"
    return str(value)


def c_rows(values: np.ndarray | list[int] | tuple[int, ...], *, width: int = 32, per_line: int = 12) -> str:
    items = [_c_int(int(v), width) for v in np.asarray(values, dtype=np.int64).ravel()]
    lines = [", ".join(items[k : k + per_line]) + "," for k in range(0, len(items), per_line)]
    return "\n".join("    " + line for line in lines)


def _bound_text(bound: int) -> str:
    """log2 of a bound, truncated (a bound below 2**62 never prints as 2^62.00)."""
    return f"2^{math.floor(math.log2(bound) * 100) / 100:.2f}" if bound > 0 else "0"


def _range_test(model: QuantModel) -> str:
    lim = model.limits
    return f"temp_mdegc < {lim.valid_lo_mdegc} || temp_mdegc > {lim.valid_hi_mdegc}"


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
        "temp_lo": lim.temp_lo_mdegc,
        "temp_hi": lim.temp_hi_mdegc,
        "accel_limit": lim.accel,
    }
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
    ctx.setdefault("family", unit.name)  # the name the shared templates test
    ctx["macros"] = macros
    return ctx


def sigmoid_offset(shift: int) -> int | None:
    """tdck_lstm_gates' ``sig`` argument as an offset into the activation table (the sigmoid gates'
    base, where their accumulators cannot leave the table: shift >= 22), None for NULL."""
    return ACT_SEGMENTS // 2 - 2 ** (30 - shift) if shift >= 22 else None


def stream_context(model: QStream) -> dict[str, object]:
    fe = model.frontend
    ctx: dict[str, object] = dict(
        family="stream",
        macros=[("DECIMATION", f"{fe.decimation}u"), ("WINDOW", f"{model.window}u")],
        kind=model.kind,
        rate_hz=f"{fe.rate_hz:g}",
        decimation=fe.decimation,
        step_hz=f"{fe.rate_hz / fe.decimation:g}",
        window=model.window,
        chunks=model.chunks,
        vector_slots=model.vector_slots,
        chunk_start=model.chunk_start,
        full_steps=model.full_steps,
        mean_scale=f"INT64_C({1 << model.mean_frac})",
        mean_frac=model.mean_frac,
        est_frac=EST_FRAC,
        est_limit=_c_int(EST_LIMIT, 64),
        layers=[
            {
                "rows": lay.wx.q.shape[0],
                "n_in": lay.wx.q.shape[1],
                "pairs": lay.pairs,
                "first_pairs": lay.first_pairs,
                "rest_pairs": lay.pairs - lay.first_pairs,
                "offset": lay.offset,
                "h_start": model.vector_slots - (len(model.layers) - k) * model.hidden_slots,
                "wx_frac": lay.wx.frac,
                "wh_frac": lay.wh.frac,
                "acc_frac": lay.acc_frac,
                "acc_bound_text": _bound_text(lay.acc_bound),
                "w": c_rows(lay.kernel_weights(), per_line=4 + 4 * lay.pairs),
                "row_words": 4 + 4 * lay.pairs,  # a unit's block: 4 biases, then 4 words per pair
                "rest_w": 4 + 4 * lay.first_pairs,  # spread schedule: the block's words of dot_rest
                "rest_v": lay.offset + 2 * lay.first_pairs,  # ... and its first slot of state->vec
                # spread schedule: the layer's tasks are task_first .. task_end - 1, UNIT_TASKS per unit
                "task_first": len(model.inputs) + len(UNIT_TASKS) * model.hidden_size * k,
                "task_end": len(model.inputs) + len(UNIT_TASKS) * model.hidden_size * (k + 1),
                "w_words": lay.kernel_weights().size,
                "shift": lay.shift,
            }
            for k, lay in enumerate(model.layers)
        ],
        hidden=model.hidden_size,
        sig_offset={lay.shift: sigmoid_offset(lay.shift) for lay in model.layers},
        inputs=[
            {
                "mu": _c_int(q.mu_q, 64),
                "inv": _c_int(q.inv_q, 64),
                "d_max": _c_int(q.d_max, 64),
                "pre_shift": q.pre_shift,
                "shift": q.shift,
                "doc": f"({q.name} - {q.mean:.6g} {q.unit}) / {q.std:.6g} {q.unit}",
            }
            for q in model.inputs
        ],
        act_table=c_rows(ACT_KNOT, per_line=12),
        act_knots=ACT_KNOT.size,
        schedule=model.schedule,
        tasks=model.tasks,
        unit_tasks=UNIT_TASKS,  # the order of a unit's tasks (the C's switch follows it)
        # spread schedule: one dot-product function per pair count of a task (first pairs, rest)
        dot_pair_counts=sorted(
            {n for lay in model.layers for n in (lay.first_pairs, lay.pairs - lay.first_pairs)}
        ),
        hidden_slots=model.hidden_slots,
    )
    if model.head is not None:
        ctx["head"] = {
            "w": c_rows(model.head.w.q),
            "frac": model.head.w.frac,
            "shift": model.head.shift,
            "bias": _c_int(model.head.bias_q, 64),
            "acc_bound_text": _bound_text(model.head.acc_bound),
            "may_saturate": model.head.may_saturate,
            "h_start": model.vector_slots - model.hidden_slots,
        }
    return ctx


def physics_context(model: QPhysics) -> dict[str, object]:
    tf = model.temp_frac

    def values(t: QTerm) -> dict[str, object]:
        out: dict[str, object] = {}
        if t.filter is not None:
            f = t.filter
            out |= {"c": f.c_q, "b0": f.b_q, "shift": f"{f.shift}u", "step_scale": 2 ** (tf - f.shift)}
        if t.gain is not None:
            out["q"] = t.gain.q
        if t.margin_q is not None:
            out |= {"margin": t.margin_q, "margin_text": f"{t.margin_q} (Q{tf} mdegC)"}
        return out

    return {
        "family": registry.PHYSICS_RENDERER,  # the template families/physics/_physics.c.j2
        "rate_hz": f"{model.rate_hz:g}",
        "tf": tf,
        "centre": model.centre_mdegc,
        "frac": model.frac,
        "bound_text": _bound_text(model.bound),
        "clip_lo": model.clip_lo_mdegc,
        "clip_hi": model.clip_hi_mdegc,
        "filters": [
            {
                "name": f.name,
                "tau": f"{f.tau_s:g}",
                "shift": f.shift,
                "c_real": f"{f.c_real:.9g}",
                "b0_real": f"{f.b0_real:.9g}",
            }
            for f in model.filters
        ],
        "words": physics_state_words(model),
        "terms": [{"on": True, **physics_snippets(t.fixed, values(t))} for t in model.terms],
        "u_source": "t_pm" if model.poly_reads is None else f"state->{model.poly_reads}",
        "u_shift": model.u_shift,
        "coefficients": c_rows(model.coefficients_q, per_line=4),
    }


KERNEL_FILE = "tdc_kernels.h"
PHYSICS_KERNEL_FILE = "tdc_physics_kernels.h"  # shipped with physics modules only
PHYSICS_KERNEL_HEADER = KERNEL_HEADER.parent / PHYSICS_KERNEL_FILE


def header_version(path: Path, macro: str) -> int:
    """A kernel header's ``#define MACRO N``: the generated modules check it, declared in the header only."""
    found = re.search(rf"^#define {macro} (\d+)", path.read_text(encoding="utf-8"), re.MULTILINE)
    if found is None:
        raise UserError(f"{path}: no '#define {macro} N'")
    return int(found.group(1))


TEMPLATES = Path(__file__).with_name("templates")  # the shared templates; each family's are in its unit


def _environment() -> jinja2.Environment:
    family_dirs = sorted({unit.template.parent for unit in family_entries()} - {TEMPLATES})
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader([TEMPLATES, *family_dirs]),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )
    env.globals["kernels_version"] = header_version(KERNEL_HEADER, "TDCK_VERSION")
    env.globals["physics_kernels_version"] = header_version(PHYSICS_KERNEL_HEADER, "TDCP_VERSION")
    return env


def kernel_header() -> str:
    """The kernel library as shipped (its Q-format block checked against codegen.qformats)."""
    text = KERNEL_HEADER.read_text(encoding="utf-8")
    if header_with_block(text) != text:
        raise UserError(f"{KERNEL_HEADER}: Q-format block out of date (python -m codegen.qformats --write)")
    return text


def render_sources(model: QuantModel, name: str, sha256: str, notes: tuple[str, ...] = ()) -> dict[str, str]:
    """``{NAME.h: text, NAME.c: text, tdc_kernels.h: text}`` and the family's own kernel headers
    (``tdc_physics_kernels.h`` for a physics model); ``notes`` are lines for the header's comment."""
    env = _environment()
    ctx = _context(model, validate_name(name), sha256)
    ctx["notes"] = [textwrap.wrap(note, 92) for note in notes]
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


def activation_summary(acc_frac: int) -> dict[str, object]:
    errors = activation_errors(acc_frac, C_FRAC)
    return {
        "method": f"one table of tanh(x) + 1 in Q15 over x in -8 .. 8, {ACT_SEGMENTS} segments: "
        "offline-computed knots (uint16, moved by half the chords' deviation), linear interpolation between them; sigmoid(z) = the same "
        "table at z / 2, in Q16; tanh in Q15",
        "table_bytes": 2 * ACT_KNOT.size,
        "measured_at_acc_frac_bits": acc_frac,
        **{kind: err.to_dict() for kind, err in errors.items()},
    }
