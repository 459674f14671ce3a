"""The stream family's template variables (``_stream.c.j2``), state struct members and table sizes."""

from __future__ import annotations

from codegen.activations import ACT_KNOT
from codegen.families.stream.quantise import EST_LIMIT, UNIT_TASKS, QStream
from codegen.qformats import ACT_SEGMENTS, C_FRAC, EST_FRAC
from codegen.render import Field, bound_text, c_int, c_rows
from codegen.step_units import STEP_UNITS


def stream_state_fields(model: QStream, common: list[Field]) -> list[Field]:
    """The stream family's state members, the common ones (flags, samples) placed among them."""
    lsb = STEP_UNITS[model.limits.unit].short  # the output LSB: 1/16 ug, or 1/16000 deg/s or Pa
    unit = "mdegC" if model.kind == "temperature" else lsb
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
        Field("int32_t", "estimate", (), f"held drift estimate, {lsb}, whole part (floor)"),
        Field("uint32_t", "estimate_frac", (), f"its fraction, 1/2^16 of {lsb}"),
        Field("uint32_t", "shaper", (), f"output rounding: accumulated fractions, 1/2^16 of {lsb}"),
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


def stream_tables(model: QStream) -> dict[str, int]:
    if not model.layers:
        return {}
    return {
        "activation_table": 2 * ACT_KNOT.size,
        "weights": sum(2 * lay.w_padded.size for lay in model.layers) + 4 * model.hidden_size,
        "biases": sum(4 * lay.b.size for lay in model.layers),
    }


def sigmoid_offset(shift: int) -> int | None:
    """tdck_lstm_gates' ``sig`` argument as an offset into the activation table (the sigmoid gates'
    base, where their accumulators cannot leave the table: shift >= 22), None for NULL."""
    return ACT_SEGMENTS // 2 - 2 ** (30 - shift) if shift >= 22 else None


def stream_context(model: QStream) -> dict[str, object]:
    fe = model.frontend
    ctx: dict[str, object] = dict(
        macros=[("DECIMATION", f"{fe.decimation}u"), ("WINDOW", f"{model.window}u")],
        network_step_field="phase",  # the network (or the persistence mean) steps at phase 0
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
        est_limit=c_int(EST_LIMIT, 64),
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
                "acc_bound_text": bound_text(lay.acc_bound),
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
                "mu": c_int(q.mu_q, 64),
                "inv": c_int(q.inv_q, 64),
                "d_max": c_int(q.d_max, 64),
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
            "bias": c_int(model.head.bias_q, 64),
            "acc_bound_text": bound_text(model.head.acc_bound),
            "may_saturate": model.head.may_saturate,
            "h_start": model.vector_slots - model.hidden_slots,
        }
    return ctx
