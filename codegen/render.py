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

import jinja2
import numpy as np

from codegen import __version__
from codegen.activations import (
    ACT_FRAC,
    ACT_MAX,
    EXTRA_BITS,
    RAW_FRAC,
    RAW_MAX,
    SLOPE_SHIFT,
    TABLE_FRAC,
    TABLE_LAST,
    TABLE_STEP_BITS,
    TANH_TABLE,
    activation_errors,
)
from codegen.quantize import (
    C_FRAC,
    EST_FRAC,
    EST_LIMIT,
    FLAG_INPUT_CLAMPED,
    FLAG_SATURATED,
    FLAG_TEMP_OUT_OF_RANGE,
    X_MAX,
    Z_FRAC,
    QPla,
    QStream,
    QuantModel,
)
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
    """State struct members, widest alignment first (no interior padding)."""
    common = [
        Field("uint32_t", "flags", (), "sticky FLAG_* bits"),
        Field("uint32_t", "samples", (), "samples since init (saturating)"),
    ]
    if not isinstance(model, QStream):
        return common
    unit = "mdegC" if model.kind == "temperature" else "1/16 ug"
    fields = [
        Field("int64_t", "window_sum", (), f"exact sum of the window, {unit}"),
        Field("int32_t", "window", (model.window,), f"ring buffer of clamped inputs, {unit}"),
    ]
    L, H = len(model.layers), model.hidden_size
    if L:
        fields.append(Field("int32_t", "c", (L, H), "cell states, Q7.24"))
        fields.append(Field("int32_t", "h", (L, H), "hidden states, Q30"))
    fields.append(Field("int32_t", "estimate", (), "held drift estimate, 1/16 ug, whole part (floor)"))
    if model.kind == "temperature":
        fields.insert(
            1,
            Field("int64_t", "prev_mean", (), f"window mean at the previous step, Q{model.mean_frac} mdegC"),
        )
    fields += [
        Field("uint32_t", "estimate_frac", (), "its fraction, 1/2^16 of 1/16 ug"),
        Field("uint32_t", "shaper", (), "output rounding: accumulated fractions, 1/2^16 of 1/16 ug"),
        Field("uint32_t", "window_pos", (), "next ring slot"),
        Field("uint32_t", "window_fill", (), "samples in the window"),
        Field("uint32_t", "phase", (), "n mod decimation; the network steps at 0"),
        Field("uint32_t", "steps", (), "network steps since reset (saturating)"),
        *common,
    ]
    return fields


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
    sizes = {"model_id_string": len("sha256:") + 64 + 1}
    if isinstance(model, QStream):
        if model.layers:
            sizes["tanh_table"] = 4 * len(TANH_TABLE)
            sizes["weights"] = sum(4 * (lay.wx.q.size + lay.wh.q.size) for lay in model.layers) + 4 * (
                model.hidden_size
            )
            sizes["biases"] = sum(8 * lay.b.size for lay in model.layers)
    elif isinstance(model, QPla):
        sizes["pla_tables"] = (
            4 * len(model.splits_mdegc) + 4 * len(model.slopes_q) + 8 * len(model.intercepts_q)
        )
    else:
        sizes["poly3_coefficients"] = 16
    return sizes


def _c_int(value: int, width: int = 32) -> str:
    value = int(value)
    if width == 64:
        return f"INT64_C({value})"
    return str(value)


def _rows(values: np.ndarray | list[int] | tuple[int, ...], *, width: int = 32, per_line: int = 12) -> str:
    items = [_c_int(int(v), width) for v in np.asarray(values, dtype=np.int64).ravel()]
    lines = [", ".join(items[k : k + per_line]) + "," for k in range(0, len(items), per_line)]
    return "\n".join("    " + line for line in lines)


def _bound_text(bound: int) -> str:
    """log2 of a bound, truncated (a bound below 2**62 never prints as 2^62.00)."""
    return f"2^{math.floor(math.log2(bound) * 100) / 100:.2f}" if bound > 0 else "0"


def _matrix_rows(q: np.ndarray) -> str:
    return "\n".join("    { " + ", ".join(str(int(v)) for v in row) + " }," for row in np.atleast_2d(q))


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
    macros: list[tuple[str, object]] = [
        ("VALID_TEMP_MIN_MDEGC", lim.valid_lo_mdegc),
        ("VALID_TEMP_MAX_MDEGC", lim.valid_hi_mdegc),
    ]
    if isinstance(model, QStream):
        fe = model.frontend
        ctx.update(
            family="stream",
            kind=model.kind,
            rate_hz=f"{fe.rate_hz:g}",
            decimation=fe.decimation,
            step_hz=f"{fe.rate_hz / fe.decimation:g}",
            window=model.window,
            mean_scale=f"INT64_C({1 << model.mean_frac})",
            mean_frac=model.mean_frac,
            est_frac=EST_FRAC,
            est_one=1 << EST_FRAC,
            est_limit=_c_int(EST_LIMIT, 64),
            layers=[
                {
                    "rows": lay.wx.q.shape[0],
                    "n_in": lay.wx.q.shape[1],
                    "wx_frac": lay.wx.frac,
                    "wh_frac": lay.wh.frac,
                    "acc_frac": lay.acc_frac,
                    "acc_bound_text": _bound_text(lay.acc_bound),
                    "wx": _matrix_rows(lay.wx.q),
                    "wh": _matrix_rows(lay.wh.q),
                    "b": _rows(lay.b, width=64, per_line=4),
                    "shift": lay.z_shift,
                }
                for lay in model.layers
            ],
            hidden=model.hidden_size,
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
            x_max=X_MAX,
            tanh_table=_rows(TANH_TABLE, per_line=8),
            table_last=TABLE_LAST,
            raw_last=_c_int(int(TANH_TABLE[TABLE_LAST]) << EXTRA_BITS, 64),
            raw_max=_c_int(RAW_MAX, 64),
            raw_one=_c_int(1 << RAW_FRAC, 64),
            one_q62=f"UINT64_C({1 << (2 * TABLE_FRAC)})",
            slope_shift=SLOPE_SHIFT,
            extra_scale=1 << EXTRA_BITS,
            tanh_round=1 << (RAW_FRAC - ACT_FRAC - 1),
            tanh_out_shift=RAW_FRAC - ACT_FRAC,
            sigmoid_round=1 << (RAW_FRAC - ACT_FRAC),
            sigmoid_out_shift=RAW_FRAC + 1 - ACT_FRAC,
            act_max=ACT_MAX,
            act_frac=ACT_FRAC,
            tanh_shift=Z_FRAC - TABLE_STEP_BITS,
            sigmoid_shift=Z_FRAC + 1 - TABLE_STEP_BITS,
            cell_tanh_shift=C_FRAC - TABLE_STEP_BITS,
            ig_shift=ACT_FRAC - C_FRAC,
        )
        if model.head is not None:
            ctx["head"] = {
                "w": _rows(model.head.w.q),
                "frac": model.head.w.frac,
                "shift": model.head.shift,
                "bias": _c_int(model.head.bias_q, 64),
                "acc_bound_text": _bound_text(model.head.acc_bound),
            }
        macros += [
            ("SAMPLE_RATE_HZ", f"{fe.rate_hz:g}"),
            ("DECIMATION", f"{fe.decimation}u"),
            ("WINDOW", f"{model.window}u"),
        ]
    elif isinstance(model, QPla):
        ctx.update(
            family="piecewise_linear",
            splits=_rows(model.splits_mdegc) if model.splits_mdegc else "",
            n_splits=len(model.splits_mdegc),
            n_intervals=len(model.slopes_q),
            slopes=_rows(model.slopes_q),
            intercepts=_rows(model.intercepts_q, width=64, per_line=4),
            frac=model.frac,
        )
    else:
        ctx.update(
            family="cubic",
            coefficients=_rows(model.coefficients_q),
            frac=model.frac,
            u_shift=model.u_shift,
            t_ref=model.t_ref_mdegc,
            clip_lo=model.clip_lo_mdegc,
            clip_hi=model.clip_hi_mdegc,
        )
    ctx["macros"] = macros
    return ctx


def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.PackageLoader("codegen", "templates"),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )


def render_sources(model: QuantModel, name: str, sha256: str, notes: tuple[str, ...] = ()) -> dict[str, str]:
    """``{NAME.h: text, NAME.c: text}``; ``notes`` are lines for the header's comment."""
    env = _environment()
    ctx = _context(model, validate_name(name), sha256)
    ctx["notes"] = [textwrap.wrap(note, 92) for note in notes]
    return {
        f"{name}.h": env.get_template("module.h.j2").render(ctx),
        f"{name}.c": env.get_template("module.c.j2").render(ctx),
    }


def render_template(template: str, model: QuantModel, name: str, sha256: str, **extra: object) -> str:
    """Render one of the shipped auxiliary templates (the test and benchmark harnesses)."""
    ctx = _context(model, name, sha256)
    ctx.update(extra)
    return _environment().get_template(template).render(ctx)


def manifest_json(manifest: dict[str, object]) -> str:
    return json.dumps(manifest, indent=2, sort_keys=True) + "\n"


def activation_summary() -> dict[str, object]:
    errors = activation_errors(Z_FRAC, C_FRAC)
    return {
        "method": f"tanh table of {TABLE_LAST + 1} uint32 Q31 entries (step 1/{1 << TABLE_STEP_BITS}, inputs "
        f"0..{TABLE_LAST >> TABLE_STEP_BITS}) with cubic Hermite interpolation (slopes 1 - tanh^2 from the "
        "entries); sigmoid(z) = (1 + tanh(z/2)) / 2; outputs Q30, rounded once",
        "table_bytes": 4 * len(TANH_TABLE),
        **{kind: err.to_dict() for kind, err in errors.items()},
    }
