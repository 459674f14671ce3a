"""The manifest (JSON) of a generated module: hash, formats, rates, ranges, bounds, sizes.

The bounds are the generation-time proofs of each family's quantiser (its unit's manifest section,
codegen/families/), stated with their headroom in bits (log2 of limit / worst case), so that every
saturation the C can reach is documented.
"""

from __future__ import annotations

import math

from codegen import __version__
from codegen.family import QuantModel, family_of
from codegen.quantize import ACCEL_PER_MG
from codegen.rate import ANY_RATE_MILLIHZ
from codegen.render import FLAGS, KERNEL_FILE, state_bytes, state_fields, table_bytes

FORMAT = "mems-tdc-codegen-manifest"
FORMAT_VERSION = 3


def memoryless_rates() -> dict[str, object]:
    """The ``rates`` of a memoryless model's manifest: any rate."""
    return {"sample_rate_hz": None, "sample_rate_millihz": ANY_RATE_MILLIHZ, "memoryless": True}


def six_digits(value: float) -> float | str:
    """Six significant digits (stable JSON); infinities as strings."""
    if math.isinf(value):
        return "inf"
    return float(f"{value:.6g}")


def build_manifest(
    model: QuantModel, *, name: str, sha256: str, valid_temp_range_c: tuple[float, float]
) -> dict[str, object]:
    lim = model.limits
    tables = table_bytes(model)
    unit = family_of(model)
    body = unit.manifest(model)
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
            "step": f"int32_t {name}_step({name}_state_t *state, int32_t accel_q4ug, int32_t temp_mdegc)",
            "run": f"void {name}_run({name}_state_t *state, const int32_t *accel_q4ug, "
            "const int32_t *temp_mdegc, int32_t *out_q4ug, size_t n)",
            "model_id": f"const char *{name}_model_id(void)",
            **(
                {"restore": f"int {name}_restore({name}_state_t *state, const {name}_state_t *saved)"}
                if unit.restore
                else {}
            ),
        },
        "units": {
            "accel_in": "int32, 1/16 micro-g (16000 LSB = 1 mg)",
            "temp_in": "int32 milli-degC",
            "out": "int32, 1/16 micro-g, compensated = raw - drift estimate, saturated",
        },
        "valid_temp_range_c": list(valid_temp_range_c),
        "valid_temp_range_mdegc": [lim.valid_lo_mdegc, lim.valid_hi_mdegc],
        "input_limits": {
            "accel_lsb": [-lim.accel, lim.accel],
            "accel_g": [-lim.accel / ACCEL_PER_MG / 1000, lim.accel / ACCEL_PER_MG / 1000],
            "accel_clamped": unit.clamps_accel(model),  # False: the acceleration passes through as it comes
            "temp_mdegc": [lim.temp_lo_mdegc, lim.temp_hi_mdegc],
        },
        "flags": dict(FLAGS),
        "sizes": {
            "flash_table_bytes": sum(tables.values()),
            "flash_tables": tables,
            "ram_state_bytes": state_bytes(state_fields(model)),
        },
        **body,
    }
