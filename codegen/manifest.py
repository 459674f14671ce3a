"""The manifest (JSON) of a generated module: hash, formats, rates, ranges, bounds, sizes.

The bounds are the generation-time proofs of each family's quantiser (its unit's manifest section,
codegen/families/), stated with their headroom in bits (log2 of limit / worst case), so that every
saturation the C can reach is documented.
"""

from __future__ import annotations

import math

from codegen import __version__
from codegen.family import QuantModel, family_of
from codegen.rate import ANY_RATE_MILLIHZ
from codegen.render import FLAGS, KERNEL_FILE, state_bytes, state_fields, table_bytes
from codegen.step_units import LSB_PER_UNIT, STEP_UNITS

FORMAT = "mems-tdc-codegen-manifest"
FORMAT_VERSION = 4  # 4: api, units and input_limits in the channel's own words and clamps


def memoryless_rates() -> dict[str, object]:
    """The ``rates`` of a memoryless model's manifest: any rate."""
    return {"sample_rate_hz": None, "sample_rate_millihz": ANY_RATE_MILLIHZ, "memoryless": True}


def six_digits(value: float) -> float | str:
    """Six significant digits (stable JSON); infinities as strings."""
    if math.isinf(value):
        return "inf"
    return float(f"{value:.6g}")


def input_limits(model: QuantModel) -> dict[str, object]:
    """``input_limits``: where the step clamps each input, exactly as its C does (the family's
    :class:`~codegen.family.InputClamps`, the declaration the template renders the clamps from),
    in LSB and in the channel's unit; each clamp sets ``input_clamped`` in the flags."""
    clamps = family_of(model).input_clamps(model)
    step = STEP_UNITS[model.limits.unit]
    signal: dict[str, object] = {"argument": step.argument, "unit": step.label, "clamped": False}
    if clamps.signal_lsb is None:
        signal["note"] = (
            "never clamped: the drift is subtracted from the input as it comes (the output saturates)"
        )
    else:
        limit = clamps.signal_lsb
        signal |= {
            "clamped": True,
            "lsb": [-limit, limit],
            "range": [-limit / LSB_PER_UNIT, limit / LSB_PER_UNIT],
        }
    temp: dict[str, object] = {"argument": "temp_mdegc", "clamped": False}
    if clamps.temp_mdegc is None:
        temp["note"] = "never clamped: the model does not read it beyond the valid-range flag"
    else:
        temp |= {"clamped": True, "mdegc": list(clamps.temp_mdegc)}
    return {"input": signal, "temp": temp}


def build_manifest(
    model: QuantModel, *, name: str, sha256: str, valid_temp_range_c: tuple[float, float]
) -> dict[str, object]:
    lim = model.limits
    tables = table_bytes(model)
    unit = family_of(model)
    body = unit.manifest(model)
    step = STEP_UNITS[lim.unit]
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "generator": f"mems-tdc codegen {__version__}",
        "name": name,
        "method": model.method,
        "files": {
            "header": f"{name}.h",
            "source": f"{name}.c",
            "kernels": KERNEL_FILE,
            **{key: header.name for key, header in unit.kernels.items()},
        },
        "model": {"sha256": sha256, "id": f"sha256:{sha256}"},
        "api": {
            "init": f"void {name}_init({name}_state_t *state)",
            "reset": f"void {name}_reset({name}_state_t *state)",
            "step": f"int32_t {name}_step({name}_state_t *state, int32_t {step.argument}, int32_t temp_mdegc)",
            "run": f"void {name}_run({name}_state_t *state, const int32_t *{step.argument}, "
            f"const int32_t *temp_mdegc, int32_t *{step.output}, size_t n)",
            "model_id": f"const char *{name}_model_id(void)",
            **(
                {"restore": f"int {name}_restore({name}_state_t *state, const {name}_state_t *saved)"}
                if unit.restore
                else {}
            ),
        },
        "units": {
            "unit": step.label,
            "lsb_per_unit": LSB_PER_UNIT,
            "in": f"{step.argument}: int32 {step.quantity} in {step.lsb}",
            "temp_in": "temp_mdegc: int32 milli-degC",
            "out": f"int32 {step.quantity} in {step.short}, compensated = raw - drift estimate, saturated",
        },
        "valid_temp_range_c": list(valid_temp_range_c),
        "valid_temp_range_mdegc": [lim.valid_lo_mdegc, lim.valid_hi_mdegc],
        "input_limits": input_limits(model),
        "flags": dict(FLAGS),
        "sizes": {
            "flash_table_bytes": sum(tables.values()),
            "flash_tables": tables,
            "ram_state_bytes": state_bytes(state_fields(model)),
        },
        **body,
    }
