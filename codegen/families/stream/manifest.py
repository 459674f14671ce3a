"""The stream family's manifest section: rates, schedule, front end, and the quantiser's bounds
(:mod:`codegen.families.stream.quantise`) with their headroom in bits."""

from __future__ import annotations

from codegen.activations import ACT_ERROR_LSB, ACT_KNOT, activation_errors
from codegen.families.stream.quantise import QLayer, QMatrix, QStream
from codegen.fixedpoint import INT32_MAX, INT64_MAX, headroom_bits
from codegen.manifest import six_digits
from codegen.qformats import ACT_SEGMENTS, C_FRAC, GATE_FRAC, H_FRAC, TANH_FRAC, X_FRAC, X_MIN_FRAC
from codegen.rate import rate_millihz
from codegen.step_units import STEP_UNITS
from trainer.dlstm.realtime import PERSISTENCE_KIND

CELL_LIMIT = INT32_MAX / 2.0**C_FRAC


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
            "smoothed_signal": "temperature"
            if model.kind == "temperature"
            else STEP_UNITS[model.limits.unit].quantity,
            "window_samples": model.window,
            "accel_window": fe.accel_window,
            "temp_window": fe.temp_window,
            "window_sums": f"running sum from phase {model.chunk_start} and {model.chunks} period sums (exact)",
            "mean": "one rounding division per step"
            + (f" to Q{model.mean_frac}" if model.layers else " (the estimate, output LSB)"),
        },
    }
    if not model.layers:
        out["quantisation"] = {"rounding": "half away from zero", "estimate": "window mean, output LSB"}
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
            "head": "int32 weights, int64 bias and accumulator, estimate int32 output LSB (flagged)",
            "window_mean": f"int64 Q{model.mean_frac} of the input unit "
            + ("(mdegC)" if model.kind == "temperature" else f"({STEP_UNITS[model.limits.unit].short})"),
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
            "output_mean": model.frontend.output_mean,  # in the channel's unit (units.unit)
            "output_std": model.frontend.output_std,
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
