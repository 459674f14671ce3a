"""The manifest (JSON) of a generated module: hash, formats, rates, ranges, bounds, sizes.

The bounds are the generation-time proofs of :mod:`codegen.quantize`, stated with their headroom
in bits (log2 of limit / worst case), so that every saturation the C can reach is documented.
"""

from __future__ import annotations

import math

from codegen import __version__
from codegen.activations import ACT_ERROR_LSB
from codegen.family import QuantModel, family_of
from codegen.fixedpoint import INT32_MAX, INT64_MAX, headroom_bits
from codegen.qformats import (
    C_FRAC,
    GATE_FRAC,
    H_FRAC,
    TANH_FRAC,
    X_FRAC,
    X_MIN_FRAC,
)
from codegen.quantize import (
    ACCEL_PER_MG,
    QLayer,
    QMatrix,
    QPhysics,
    QStream,
)
from codegen.rate import ANY_RATE_MILLIHZ, rate_millihz
from codegen.render import (
    FLAGS,
    KERNEL_FILE,
    activation_summary,
    state_bytes,
    state_fields,
    table_bytes,
)
from trainer.dlstm.realtime import PERSISTENCE_KIND

FORMAT = "mems-tdc-codegen-manifest"
FORMAT_VERSION = 3
CELL_LIMIT = INT32_MAX / 2.0**C_FRAC


def memoryless_rates() -> dict[str, object]:
    """The ``rates`` of a memoryless model's manifest: any rate."""
    return {"sample_rate_hz": None, "sample_rate_millihz": ANY_RATE_MILLIHZ, "memoryless": True}


def six_digits(value: float) -> float | str:
    """Six significant digits (stable JSON); infinities as strings."""
    if math.isinf(value):
        return "inf"
    return float(f"{value:.6g}")


def _matrix(m: QMatrix, storage: str) -> dict[str, object]:
    return {
        "storage": storage,
        "frac_bits": m.frac,
        "input_frac_bits": m.input_frac,
        "input_max": m.input_max,
        "acc_share_bound": m.acc_bound,
    }


def _layer(layer: QLayer) -> dict[str, object]:
    return {
        "w_x": _matrix(layer.wx, "int16"),
        "w_h": _matrix(layer.wh, "int16"),
        "bias_format": f"int32 Q{layer.acc_frac}",
        "accumulator": f"int32 Q{layer.acc_frac}, initialised with the bias (SMLAD on a Cortex-M4)",
        "acc_frac_bits": layer.acc_frac,
        "acc_bound": layer.acc_bound,
        "acc_limit": INT32_MAX,
        "acc_headroom_bits": six_digits(layer.acc_headroom),
        "activation_shift": layer.shift,
        "z_bound": six_digits(layer.z_bound),
        "z_note": "the accumulator indexes the activation table directly; beyond the table (|z| >= 8 for "
        "tanh, 16 for sigmoid) the functions are constant",
        "forget_gate_max": six_digits(layer.forget_max_q / 2.0**GATE_FRAC),
        "cell_bound": six_digits(layer.cell_bound),
        "cell_limit": six_digits(CELL_LIMIT),
        "cell_headroom_bits": six_digits(headroom_bits(layer.cell_bound, CELL_LIMIT)),
        "cell_saturation_reachable": bool(layer.cell_bound > CELL_LIMIT),
    }


def stream_manifest(model: QStream) -> dict[str, object]:
    fe = model.frontend
    out: dict[str, object] = {
        "rates": {
            "sample_rate_hz": fe.rate_hz,
            "sample_rate_millihz": rate_millihz(fe.rate_hz),
            "decimation": fe.decimation,
            "network_step_hz": six_digits(fe.rate_hz / fe.decimation),
        },
        **(
            {
                "schedule": {
                    "name": model.schedule,
                    "tasks_per_step": model.tasks if model.schedule == "spread" else 1,
                    "latency_samples": model.latency_samples,
                    "latency_s": six_digits(model.latency_samples / fe.rate_hz),
                }
            }
            if model.layers
            else {}
        ),
        "frontend": {
            "kind": PERSISTENCE_KIND if not model.layers else model.kind,
            "smoothed_signal": "temperature" if model.kind == "temperature" else "acceleration",
            "window_samples": model.window,
            "accel_window": fe.accel_window,
            "temp_window": fe.temp_window,
            "window_sums": f"running sum from phase {model.chunk_start} and {model.chunks} period sums (exact)",
            "mean": "one rounding division per step"
            + (f" to Q{model.mean_frac}" if model.layers else " (the estimate, accel LSB)"),
        },
    }
    if not model.layers:
        out["quantisation"] = {"rounding": "half away from zero", "estimate": "window mean, accel LSB"}
        out["macs_per_network_step"] = 0
        return out
    head = model.head
    assert head is not None
    out["quantisation"] = {
        "rounding": "network: half up (floor(x + 1/2)); inputs, head: half away from zero",
        "formats": {
            "inputs_x": f"int16 Q{X_FRAC} (+-8) or wider, down to Q{X_MIN_FRAC} (+-32), when layer 0 loses no "
            "accumulator bit (x_frac_bits per input); clamping is flagged",
            "weights": f"int16; per layer Q(A - x frac) for each layer-0 input, Q(A - {H_FRAC}) otherwise",
            "accumulators": "int32 Q(A) per gate row, initialised with the int32 bias; bounded below 2^31",
            "gates_i_f_o": f"Q{GATE_FRAC} (table sigmoid)",
            "g_and_tanh_c": f"Q{TANH_FRAC} (table tanh)",
            "h": f"int16 Q{H_FRAC}",
            "cell_state": f"int32 Q7.{C_FRAC}, saturated at the int32 limits (flagged)",
            "head": "int32 weights, int64 bias and accumulator, estimate int32 accel LSB (flagged)",
            "window_mean": f"int64 Q{model.mean_frac} of the input unit (1/16 ug or mdegC)",
        },
        "activation_error_bound_lsb": ACT_ERROR_LSB,
        "inputs": [
            {
                "name": q.name,
                "mean": q.mean,
                "std": q.std,
                "unit": q.unit,
                "mu_q": q.mu_q,
                "pre_shift": q.pre_shift,
                "inv_q": q.inv_q,
                "shift": q.shift,
                "d_max": q.d_max,
                "x_frac_bits": q.frac,
                "product_headroom_bits": six_digits(q.product_headroom),
            }
            for q in model.inputs
        ],
        "layers": [_layer(layer) for layer in model.layers],
        "head": {
            "w": _matrix(head.w, "int32"),
            "shift": head.shift,
            "bias_q": head.bias_q,
            "acc_bound": head.acc_bound,
            "acc_headroom_bits": six_digits(headroom_bits(head.acc_bound, INT64_MAX)),
            "estimate_bound_lsb": six_digits(head.estimate_bound),
            "estimate_headroom_bits": six_digits(headroom_bits(head.estimate_bound, INT32_MAX)),
            "output_mean_mg": model.frontend.output_mean,
            "output_std_mg": model.frontend.output_std,
        },
    }
    out["activations"] = activation_summary(min(layer.acc_frac for layer in model.layers))
    out["architecture"] = {
        "input_size": len(model.inputs),
        "hidden_size": model.hidden_size,
        "num_layers": len(model.layers),
    }
    out["macs_per_network_step"] = model.macs_per_step()
    return out


def physics_manifest(model: QPhysics) -> dict[str, object]:
    return {
        "rates": {
            "sample_rate_hz": model.rate_hz,
            "sample_rate_millihz": rate_millihz(model.rate_hz),
            "note": "the filters are discretised for this rate: call NAME_step at exactly this rate",
        },
        "quantisation": {
            "rounding": "floor (filter differences, high words) and half up (Horner products, the drift): "
            "tdc_physics_kernels.h",
            "temperatures": f"int32 Q{model.temp_frac} mdegC about {model.centre_mdegc} mdegC (x, P)",
            "filter_states": f"int64 Q{model.temp_frac + 32} mdegC (the high word is the int32 temperature)",
            "clip_mdegc": [model.clip_lo_mdegc, model.clip_hi_mdegc],
            "polynomial_u": f"T_b 2^{model.u_shift} in Q31 (|u| < 2^31), re-expanded about the centre",
            "coefficients_q": list(model.coefficients_q),
            "coefficient_frac_bits": [model.frac + k for k in range(4)],
            "horner_bounds": list(model.horner_bounds),
            "drift_frac_bits": model.frac,
            "accumulator_frac_bits": model.frac + 32,
            "drift_bound": model.bound,
            "drift_headroom_bits": six_digits(headroom_bits(model.bound, INT64_MAX)),
            "filters": [
                {
                    "name": f.name,
                    "tau_s": f.tau_s,
                    "c_q": f.c_q,
                    "b0_q": f.b_q,
                    "frac_bits": 32 + f.shift,
                    "difference_shift": f.shift,
                    "state_error_bound_mdegc": six_digits(f.error_mdegc),
                    "state_error_bound_drift_mg": six_digits(f.error_mg),
                }
                for f in model.filters
            ],
            "gains": [{"name": g.name, "q": g.q, "difference_bound": g.diff_bound} for g in model.gains],
        },
        "model_tag": model.tag,
        "power_on": "filters start in equilibrium at the first sample; the play operator at T_pm (mid-branch)",
        "save_restore": "copy NAME_state_t; NAME_restore checks model_tag and keeps the hysteresis branch",
        "macs_per_sample": 3 + 2 * len(model.filters) + len(model.gains),
    }


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
