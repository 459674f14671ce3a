"""Float32 anchors for bench/bench_cortex_m.py: the same DLSTM as plain float32 C, with the API of a
generated module (NAME_init/reset/step/run/model_id, the header macros the harnesses read), so
that the target benchmark times it with the same app in the same run.

Two variants: ``libm`` (sigmoid = 1 / (1 + expf(-x)), tanhf: what a firmware engineer writes
first) and ``fast`` (a rational tanh, Lambert's continued fraction to x^7/x^6, clamped at
|x| >= 4.97, error below 2e-7; sigmoid(x) = (1 + tanh(x / 2)) / 2). The front end is the
generated module's (exact int64 window sums), so only the network's arithmetic differs. Not a
product: no flags beyond clamping, no saturation analysis.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from codegen.families.stream.quantise import QStream
from codegen.families.stream.spec import DlstmModelSpec
from codegen.quantize import ACCEL_PER_MG

_FAST = """static float act_tanh(float x)
{
    float x2;
    if (x > 4.97f) {
        return 1.0f;
    }
    if (x < -4.97f) {
        return -1.0f;
    }
    x2 = x * x;
    return x * (135135.0f + x2 * (17325.0f + x2 * (378.0f + x2))) / (135135.0f + x2 * (62370.0f + x2 * (3150.0f + x2 * 28.0f)));
}

static float act_sigmoid(float x)
{
    return 0.5f + 0.5f * act_tanh(0.5f * x);
}
"""

_LIBM = """#include <math.h>

static float act_tanh(float x)
{
    return tanhf(x);
}

static float act_sigmoid(float x)
{
    return 1.0f / (1.0f + expf(-x));
}
"""


def _f(value: float) -> str:
    """A float literal (always with a decimal point or exponent, then the f suffix)."""
    text = repr(float(np.float32(value)))
    return f"{text}f" if ("." in text or "e" in text) else f"{text}.0f"


def _floats(values: np.ndarray) -> str:
    return ", ".join(_f(float(v)) for v in np.asarray(values, dtype=np.float32).ravel())


def write_float_module(spec: DlstmModelSpec, q: QStream, name: str, out_dir: Path, variant: str) -> None:
    """NAME.h and NAME.c of the float32 network (``variant``: "libm" or "fast")."""
    out_dir.mkdir(parents=True, exist_ok=True)
    fe = q.frontend
    L, H = len(spec.layers), spec.layers[0].w_h.shape[1]
    temperature = q.kind == "temperature"
    n_in = 2 if temperature else 1
    up = name.upper()
    lim = q.limits
    unit = 1000.0 * (1 << q.mean_frac) if temperature else float(ACCEL_PER_MG)  # input LSB per mg or degC
    rate = 60.0 * fe.rate_hz / fe.decimation  # degC/min per degC of difference of the means
    header = f"""#ifndef {up}_H
#define {up}_H
#include <stddef.h>
#include <stdint.h>
#define {up}_DECIMATION {fe.decimation}u
#define {up}_VALID_TEMP_MIN_MDEGC {lim.valid_lo_mdegc}
#define {up}_VALID_TEMP_MAX_MDEGC {lim.valid_hi_mdegc}
#define {up}_FLAG_TEMP_OUT_OF_RANGE 1u
#define {up}_FLAG_INPUT_CLAMPED 2u
#define {up}_FLAG_SATURATED 4u
#define {up}_SAMPLE_RATE_MILLIHZ {round(fe.rate_hz * 1000)}u
#define {up}_CHECK_SAMPLE_RATE_MILLIHZ(millihz) \\
    typedef char {name}_built_for_another_sample_rate[((millihz) == {up}_SAMPLE_RATE_MILLIHZ) ? 1 : -1]
typedef struct {name}_state {{
    int64_t window_current;
    int64_t window_ring[{max(q.chunks, 1)}];
    float h[{L}][{H}];
    float c[{L}][{H}];
    float prev_mean;
    int32_t estimate;
    uint32_t ring_pos, phase, steps, flags, samples;
}} {name}_state_t;
void {name}_init({name}_state_t *state);
void {name}_reset({name}_state_t *state);
int32_t {name}_step({name}_state_t *state, int32_t accel_q4ug, int32_t temp_mdegc);
void {name}_run({name}_state_t *state, const int32_t *accel_q4ug, const int32_t *temp_mdegc, int32_t *out_q4ug, size_t n);
const char *{name}_model_id(void);
#endif
"""
    tables = []
    for k, layer in enumerate(spec.layers):
        tables.append(f"static const float wx{k}[{4 * H * layer.w_x.shape[1]}] = {{ {_floats(layer.w_x)} }};")
        tables.append(f"static const float wh{k}[{4 * H * H}] = {{ {_floats(layer.w_h)} }};")
        tables.append(f"static const float b{k}[{4 * H}] = {{ {_floats(layer.b)} }};")
    tables.append(f"static const float head_w[{H}] = {{ {_floats(spec.head_w)} }};")
    mean, std = fe.inputs_mean, fe.inputs_std
    layers = []
    for k in range(L):
        src, n = ("x", n_in) if k == 0 else (f"state->h[{k - 1}]", H)
        layers.append(f"""    for (r = 0u; r < {4 * H}u; ++r) {{
        float acc = b{k}[r];
        for (j = 0u; j < {n}u; ++j) {{
            acc += wx{k}[r * {n}u + j] * {src}[j];
        }}
        for (j = 0u; j < {H}u; ++j) {{
            acc += wh{k}[r * {H}u + j] * state->h[{k}][j];
        }}
        z[r] = acc;
    }}
    for (j = 0u; j < {H}u; ++j) {{
        float c = act_sigmoid(z[{H}u + j]) * state->c[{k}][j] + act_sigmoid(z[j]) * act_tanh(z[{2 * H}u + j]);
        state->c[{k}][j] = c;
        state->h[{k}][j] = act_sigmoid(z[{3 * H}u + j]) * act_tanh(c);
    }}""")
    inputs = (
        f"""        float mean = (float)sum / ((float)fill * {_f(unit)});
        x[0] = (mean - {_f(mean[0])}) / {_f(std[0])};
        x[1] = ((state->steps == 0u ? 0.0f : (mean - state->prev_mean) * {_f(rate)}) - {_f(mean[1])}) / {_f(std[1])};
        state->prev_mean = mean;"""
        if temperature
        else f"""        float mean = (float)sum / ((float)fill * {_f(unit)});
        x[0] = (mean - {_f(mean[0])}) / {_f(std[0])};"""
    )
    signal = "temp_mdegc" if temperature else "accel_q4ug"
    lo, hi = (lim.temp_lo_mdegc, lim.temp_hi_mdegc) if temperature else (-lim.signal_lsb, lim.signal_lsb)
    fill = (
        f"(state->steps >= {q.full_steps}u) ? {q.window}u : state->steps * {fe.decimation}u + 1u"
        if q.full_steps
        else f"{q.window}u"
    )
    source = f"""/* float32 anchor ({variant}) of the generated module: not a product, see bench/float_anchor.py */
#include <string.h>
#include "{name}.h"
{_LIBM if variant == "libm" else _FAST}
{chr(10).join(tables)}

static float network({name}_state_t *state, const float *x)
{{
    float z[{4 * H}];
    float y = {_f(spec.head_b)};
    uint32_t r;
    uint32_t j;
{chr(10).join(layers)}
    for (j = 0u; j < {H}u; ++j) {{
        y += head_w[j] * state->h[{L - 1}][j];
    }}
    return (y * {_f(fe.output_std)} + {_f(fe.output_mean)}) * {_f(ACCEL_PER_MG)};
}}

void {name}_reset({name}_state_t *state)
{{
    uint32_t flags = state->flags;
    uint32_t samples = state->samples;
    memset(state, 0, sizeof *state);
    state->flags = flags;
    state->samples = samples;
}}

void {name}_init({name}_state_t *state)
{{
    memset(state, 0, sizeof *state);
}}

int32_t {name}_step({name}_state_t *state, int32_t accel_q4ug, int32_t temp_mdegc)
{{
    int32_t v = {signal} < {lo} ? {lo} : ({signal} > {hi} ? {hi} : {signal});
    uint32_t chunks = {q.chunks}u;
    (void)temp_mdegc;
    if (state->phase == {q.chunk_start}u) {{
        if (chunks != 0u) {{
            state->window_ring[state->ring_pos] = state->window_current;
            state->ring_pos = (state->ring_pos + 1u == chunks) ? 0u : state->ring_pos + 1u;
        }}
        state->window_current = v;
    }} else {{
        state->window_current += v;
    }}
    if (state->phase == 0u) {{
        int64_t sum = state->window_current;
        uint32_t fill = {fill};
        uint32_t k;
        float x[2];
        float estimate;
        for (k = 0u; k < chunks; ++k) {{
            sum += state->window_ring[k];
        }}
{inputs}
        estimate = network(state, x);
        state->estimate = (int32_t)(estimate < 0.0f ? estimate - 0.5f : estimate + 0.5f);
        state->steps += 1u;
    }}
    state->phase = (state->phase + 1u == {fe.decimation}u) ? 0u : state->phase + 1u;
    state->samples += 1u;
    return (int32_t)((int64_t)accel_q4ug - state->estimate);
}}

void {name}_run({name}_state_t *state, const int32_t *accel_q4ug, const int32_t *temp_mdegc, int32_t *out_q4ug, size_t n)
{{
    size_t k;
    for (k = 0u; k < n; ++k) {{
        out_q4ug[k] = {name}_step(state, accel_q4ug[k], temp_mdegc[k]);
    }}
}}

const char *{name}_model_id(void)
{{
    return "float32-{variant}";
}}
"""
    (out_dir / f"{name}.h").write_text(header)
    (out_dir / f"{name}.c").write_text(source)
