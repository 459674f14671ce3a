"""Float specs -> fixed-point models, with every scale, shift and worst-case bound decided offline.

Formats (Qm.n = n fractional bits; all power-of-two scales, all rounding half away from zero):

=====================  ===========  ======================================================
quantity               storage      format
=====================  ===========  ======================================================
acceleration in/out    int32        Q4 micro-g: 1 LSB = 1/16 ug (62.5 ng), range +-134 g
temperature in         int32        milli-degC
window means           int64        Q8 of the input unit (exact running sums, one rounding division)
network inputs x       int32        Q4.27, clamped to +-16 standard deviations
weights                int16        per matrix Q(f), f chosen per matrix (see below)
layer-0 input MACs     int64        int16 w x int32 x: at most 2 per row, exact
gate pre-activation z  int32        Q15.16, bias int32 Q15.16
gates, h, tanh, sigma  int16/int32  Q0.15
cell state c           int32        Q7.24, explicit saturation at +-128 (flagged)
head weights           int16        accel LSB per unit of h, Q(f_head); estimate int32 accel LSB
PLA slopes/intercepts  int32/int64  accel LSB per mdegC and accel LSB, Q(f_pla)
cubic coefficients     int32        accel LSB, of u^k with u = (T - T_ref) / 2**p, Q(f_poly)
=====================  ===========  ======================================================

A weight matrix's ``f`` is the largest number of fractional bits such that every weight fits
int16 *and* the worst-case accumulator of every row, ``sum_j |w_q| * max|input_q|``, fits its
accumulator (int32 for the recurrent and upper-layer MACs, int64 for the layer-0 input MACs): the
MACs can then never saturate, which is proved here, not hoped for. The sum is then rounded once
to Q15.16. The manifest records each bound and its headroom in bits.

Why the network input is int32 Q4.27 rather than int16: the input's resolution feeds straight
through the network to the estimate; Q4.11 cost 0.2 .. 0.5 ug RMS on trained models (measured),
Q4.27 costs nothing measurable, and the layer-0 input has only 1 or 2 columns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from codegen.activations import ONE_Q15, sigmoid_q15, tanh_q15
from codegen.fixedpoint import (
    INT16_MAX,
    INT32_MAX,
    INT64_MAX,
    headroom_bits,
    quantise_array,
    round_half_away,
)
from codegen.spec import Checkpoint, DlstmSpec, FrontEndSpec, PersistenceSpec, PlaSpec, Poly3Spec
from trainer.errors import UserError

X_FRAC = 27
H_FRAC = 15
Z_FRAC = 16
C_FRAC = 24
MEAN_FRAC = 8
ACCEL_FRAC = 4  # the step API's acceleration unit is 2**-4 ug
ACCEL_PER_MG = 1000 << ACCEL_FRAC
MAX_WEIGHT_FRAC = 30
X_MAX = INT32_MAX  # |x_q| clamp: 16 standard deviations
H_MAX = INT16_MAX
INT64_SAFE = 1 << 62  # every int64 intermediate stays below this (one bit of margin)
DEFAULT_ACCEL_LIMIT_G = 16.0
MAX_ACCEL_LIMIT_G = 128.0  # 128 g * 16e6 LSB/g < 2**31
TEMP_LIMITS_MDEGC = (-100_000, 200_000)  # the front end clamps temperatures to -100 .. 200 degC
FLAG_TEMP_OUT_OF_RANGE = 1
FLAG_INPUT_CLAMPED = 2
FLAG_SATURATED = 4


@dataclass(frozen=True)
class Limits:
    """Input ranges the front end clamps to (documented edges; clamping sets a flag)."""

    accel: int  # |accel| clamp, in accel LSB (1/16 ug)
    temp_lo_mdegc: int = TEMP_LIMITS_MDEGC[0]
    temp_hi_mdegc: int = TEMP_LIMITS_MDEGC[1]
    valid_lo_mdegc: int = TEMP_LIMITS_MDEGC[0]  # the model's valid range, for the flag only
    valid_hi_mdegc: int = TEMP_LIMITS_MDEGC[1]


@dataclass(frozen=True)
class QMatrix:
    """An int16 weight matrix, its fractional bits, and the shift of its products to Q15.16."""

    q: np.ndarray  # int64 values within int16
    frac: int
    shift: int
    row_bounds: np.ndarray  # worst-case |accumulator| of each row, integer units
    acc_limit: int  # INT32_MAX, or the int64 limit for the layer-0 input MACs

    @property
    def acc_bound(self) -> int:
        return int(np.max(self.row_bounds, initial=0))

    @property
    def wide(self) -> bool:
        return self.acc_limit > INT32_MAX

    @property
    def headroom(self) -> float:
        return headroom_bits(self.acc_bound, self.acc_limit)


@dataclass(frozen=True)
class QInput:
    """``x_q = clamp(rshift_round(clamp(v - mu_q, +-d_max) * inv_q, shift), +-X_MAX)``, one input.

    ``d_max`` is where x saturates anyway; clamping there first keeps the product inside int64
    whatever the scale, without changing any result.
    """

    name: str
    mu_q: int
    inv_q: int
    shift: int
    d_max: int
    mean: float
    std: float
    unit: str

    @property
    def product_headroom(self) -> float:
        return headroom_bits(self.d_max * self.inv_q, INT64_MAX)


@dataclass(frozen=True)
class QLayer:
    wx: QMatrix
    wh: QMatrix
    b: np.ndarray  # Q15.16
    z_bound: int  # Q15.16
    cell_bound: float  # worst-case |c| (real units) from the gate bounds
    forget_max_q15: int

    @property
    def hidden_size(self) -> int:
        return self.wh.q.shape[1]


@dataclass(frozen=True)
class QHead:
    w: QMatrix  # (1, H), accel LSB per unit of h
    shift: int  # frac + 15
    bias_q: int  # int64, Q(shift) accel LSB (head bias * std + mean)
    estimate_bound: float  # accel LSB


@dataclass(frozen=True)
class QStream:
    """The streaming DLSTM (or persistence when ``layers`` is empty)."""

    method: str
    kind: str  # "recursive" | "temperature"
    frontend: FrontEndSpec
    limits: Limits
    inputs: tuple[QInput, ...]
    layers: tuple[QLayer, ...]
    head: QHead | None

    @property
    def window(self) -> int:
        fe = self.frontend
        return fe.temp_window if self.kind == "temperature" else fe.accel_window

    @property
    def hidden_size(self) -> int:
        return self.layers[0].hidden_size if self.layers else 0

    def macs_per_step(self) -> int:
        """Multiply-accumulates of one network step (the lower bound of its cost)."""
        total = sum(layer.wx.q.size + layer.wh.q.size for layer in self.layers)
        return total + (self.head.w.q.size if self.head else 0)


@dataclass(frozen=True)
class QPla:
    method: str
    limits: Limits
    splits_mdegc: tuple[int, ...]
    slopes_q: tuple[int, ...]  # int32, Q(frac) accel LSB per mdegC
    intercepts_q: tuple[int, ...]  # int64, Q(frac) accel LSB
    frac: int
    bound: int  # worst-case |slope_q * T + intercept_q|


@dataclass(frozen=True)
class QPoly3:
    method: str
    limits: Limits
    clip_lo_mdegc: int
    clip_hi_mdegc: int
    t_ref_mdegc: int
    u_shift: int  # u = (T - T_ref) / 2**u_shift, |u| <= 1
    coefficients_q: tuple[int, ...]  # int32, d0..d3, Q(frac) accel LSB
    frac: int
    bound: int  # worst-case |Horner accumulator|


QuantModel = QStream | QPla | QPoly3


def _choose_weight_frac(
    w: np.ndarray, what: str, *, input_max: int, min_frac: int, acc_limit: int = INT32_MAX
) -> tuple[np.ndarray, int]:
    """Largest fractional bits such that weights fit int16 and no row's MACs can overflow."""
    w = np.atleast_2d(np.asarray(w, dtype=np.float64))
    largest = float(np.max(np.abs(w))) if w.size else 0.0
    frac = (
        MAX_WEIGHT_FRAC if largest == 0 else min(MAX_WEIGHT_FRAC, math.floor(math.log2(INT16_MAX / largest)))
    )
    while frac >= min_frac:
        q = quantise_array(w, frac)
        if np.max(np.abs(q), initial=0) <= INT16_MAX and _row_bound(q, input_max) <= acc_limit:
            return q, frac
        frac -= 1
    raise UserError(
        f"{what}: weights too large for int16 with a safe accumulator "
        f"(max |w| = {largest:.4g}, row sum of |w| = {float(np.max(np.sum(np.abs(w), axis=1))):.4g})"
    )


def _row_bound(q: np.ndarray, input_max: int) -> int:
    return int(np.max(np.sum(np.abs(q), axis=1), initial=0)) * input_max


def _matrix(w: np.ndarray, what: str, in_frac: int, input_max: int, acc_limit: int) -> QMatrix:
    q, frac = _choose_weight_frac(
        w, what, input_max=input_max, min_frac=Z_FRAC - in_frac, acc_limit=acc_limit
    )
    return QMatrix(q, frac, frac + in_frac - Z_FRAC, np.sum(np.abs(q), axis=1) * input_max, acc_limit)


def _ceil_shift(value: int, shift: int) -> int:
    """An upper bound of |rshift_round(x, shift)| for |x| <= value."""
    return (value + (1 << shift) - 1) >> shift if shift else value


def _layer(spec_w_x: np.ndarray, spec_w_h: np.ndarray, spec_b: np.ndarray, index: int) -> QLayer:
    if index == 0:
        wx = _matrix(spec_w_x, "layer 0 w_x", X_FRAC, X_MAX, INT64_SAFE)
    else:
        wx = _matrix(spec_w_x, f"layer {index} w_x", H_FRAC, H_MAX, INT32_MAX)
    wh = _matrix(spec_w_h, f"layer {index} w_h", H_FRAC, H_MAX, INT32_MAX)
    b = quantise_array(spec_b, Z_FRAC)
    if np.max(np.abs(b), initial=0) > INT32_MAX:
        raise UserError(f"layer {index} bias: |b| = {float(np.max(np.abs(spec_b))):.4g} does not fit Q15.16")
    rows_x, rows_h = wx.row_bounds, wh.row_bounds
    z_rows = np.array(
        [
            _ceil_shift(int(rx), wx.shift) + _ceil_shift(int(rh), wh.shift) + abs(int(bb))
            for rx, rh, bb in zip(rows_x, rows_h, b, strict=True)
        ],
        dtype=np.int64,
    )
    z_rows = np.minimum(z_rows, INT32_MAX)  # z saturates there; the activations are flat long before
    H = wh.q.shape[1]
    i_max = sigmoid_q15(z_rows[0:H], Z_FRAC) / ONE_Q15
    f_max_q = sigmoid_q15(z_rows[H : 2 * H], Z_FRAC)
    g_max = tanh_q15(z_rows[2 * H : 3 * H], Z_FRAC) / ONE_Q15
    # |c'| <= f |c| + i |g| + 2**-25 (one rounding) -> geometric bound; f <= 32767/32768 < 1 always.
    cell = (i_max * g_max + 2.0**-25) / (1.0 - f_max_q / ONE_Q15)
    return QLayer(wx, wh, b, int(np.max(z_rows)), float(np.max(cell)), int(np.max(f_max_q)))


def _input(name: str, v_max: int, unit_per_lsb: Fraction, mean: float, std: float, unit: str) -> QInput:
    mu_q = round_half_away(Fraction(mean) / unit_per_lsb)
    gain = unit_per_lsb / Fraction(std) * (1 << X_FRAC)  # x_q per LSB of v
    shift = max(0, 23 - math.floor(math.log2(gain)))  # inv_q gets 24 significant bits when possible
    while shift <= 62:
        inv_q = round_half_away(gain * (1 << shift))
        saturating = -(-(X_MAX + 1) * (1 << shift) // inv_q)  # ceil: from here on x clamps anyway
        d_max = min(v_max + abs(mu_q), saturating)
        if d_max * inv_q < INT64_SAFE:
            return QInput(name, mu_q, inv_q, shift, d_max, mean, std, unit)
        shift -= 1
        if shift < 0 or inv_q < 256:
            break
    raise UserError(f"input '{name}': mean {mean:g} / std {std:g} {unit} cannot be scaled in int64")


def _head(spec: DlstmSpec) -> QHead:
    fe = spec.frontend
    scale = fe.output_std * ACCEL_PER_MG  # accel LSB per unit of y
    q, frac = _choose_weight_frac(spec.head_w * scale, "head", input_max=H_MAX, min_frac=1 - H_FRAC)
    shift = frac + H_FRAC
    bias_q = round_half_away(
        (Fraction(spec.head_b) * Fraction(fe.output_std) + Fraction(fe.output_mean))
        * ACCEL_PER_MG
        * Fraction(2) ** shift
    )
    w = QMatrix(q, frac, 0, np.sum(np.abs(q), axis=1) * H_MAX, INT32_MAX)
    acc_bound = w.acc_bound
    if abs(bias_q) + acc_bound >= INT64_SAFE:
        raise UserError(f"head: output mean {fe.output_mean:g} mg cannot be represented")
    return QHead(w, shift, bias_q, (acc_bound + abs(bias_q)) / 2.0**shift)


def _limits(ckpt: Checkpoint, accel_limit_g: float) -> Limits:
    if not (math.isfinite(accel_limit_g) and 0 < accel_limit_g <= MAX_ACCEL_LIMIT_G):
        raise UserError(f"--accel-limit-g must be in (0, {MAX_ACCEL_LIMIT_G:g}] g, got {accel_limit_g!r}")
    lo, hi = ckpt.valid_temp_range_c
    clip = (-(1 << 31) + 1, INT32_MAX)
    valid_lo = min(max(math.ceil(Fraction(lo) * 1000), clip[0]), clip[1])
    valid_hi = min(max(math.floor(Fraction(hi) * 1000), clip[0]), clip[1])
    return Limits(
        round(accel_limit_g * 1000 * ACCEL_PER_MG), valid_lo_mdegc=valid_lo, valid_hi_mdegc=valid_hi
    )


def _stream(spec: DlstmSpec | PersistenceSpec, limits: Limits) -> QStream:
    fe = spec.frontend
    if isinstance(spec, PersistenceSpec):
        return QStream(spec.method, "recursive", fe, limits, (), (), None)
    mean_lsb = 1 << MEAN_FRAC
    if fe.kind == "recursive":
        inputs = (
            _input(
                "accel",
                limits.accel * mean_lsb,
                Fraction(1, ACCEL_PER_MG * mean_lsb),
                fe.inputs_mean[0],
                fe.inputs_std[0],
                "mg",
            ),
        )
    else:
        t_max = max(-limits.temp_lo_mdegc, limits.temp_hi_mdegc)
        span = limits.temp_hi_mdegc - limits.temp_lo_mdegc
        rate_unit = (
            Fraction(60) * Fraction(fe.rate_hz) / (fe.decimation * 1000 * mean_lsb)
        )  # degC/min per LSB
        inputs = (
            _input(
                "temp",
                t_max * mean_lsb,
                Fraction(1, 1000 * mean_lsb),
                fe.inputs_mean[0],
                fe.inputs_std[0],
                "degC",
            ),
            _input("rate", span * mean_lsb, rate_unit, fe.inputs_mean[1], fe.inputs_std[1], "degC/min"),
        )
    layers = tuple(_layer(layer.w_x, layer.w_h, layer.b, k) for k, layer in enumerate(spec.layers))
    return QStream(spec.method, fe.kind, fe, limits, inputs, layers, _head(spec))


def _pla(spec: PlaSpec, limits: Limits) -> QPla:
    splits = tuple(
        math.ceil(Fraction(s) * 1000) for s in spec.split_points_c
    )  # T_q >= s*1000 <=> T_q >= ceil
    splits = tuple(min(max(s, -INT32_MAX), INT32_MAX) for s in splits)
    t_max = max(-limits.temp_lo_mdegc, limits.temp_hi_mdegc)
    slopes_lsb = [Fraction(v) * ACCEL_PER_MG / 1000 for v in spec.slopes_mg_per_c]  # accel LSB per mdegC
    intercepts_lsb = [Fraction(v) * ACCEL_PER_MG for v in spec.intercepts_mg]
    for frac in range(40, -1, -1):
        slopes = [round_half_away(v * (1 << frac)) for v in slopes_lsb]
        intercepts = [round_half_away(v * (1 << frac)) for v in intercepts_lsb]
        bound = max(abs(s) * t_max + abs(c) for s, c in zip(slopes, intercepts, strict=True))
        if max(abs(s) for s in slopes) <= INT32_MAX and bound < INT64_SAFE:
            return QPla(spec.method, limits, splits, tuple(slopes), tuple(intercepts), frac, bound)
    raise UserError("pla: slopes or intercepts too large for the fixed-point format")


def _poly3(spec: Poly3Spec, limits: Limits) -> QPoly3:
    lo = round_half_away(Fraction(spec.temp_range_c[0]) * 1000)
    hi = round_half_away(Fraction(spec.temp_range_c[1]) * 1000)
    if not (-INT32_MAX <= lo < hi <= INT32_MAX):
        raise UserError(f"poly3: temperature range {spec.temp_range_c} degC is outside int32 mdegC")
    t_ref = round_half_away(Fraction(spec.t_ref_c) * 1000)
    t_ref = min(max(t_ref, lo), hi)
    u_shift = max(1, math.ceil(math.log2(max(abs(lo - t_ref), abs(hi - t_ref), 1))))
    delta = t_ref - Fraction(spec.t_ref_c) * 1000  # exact: p(T - t_ref) = q(T - T_ref_int)
    e = [Fraction(c) * ACCEL_PER_MG / Fraction(1000) ** k for k, c in enumerate(spec.coefficients_mg)]
    shifted = [sum(e[k] * math.comb(k, j) * delta ** (k - j) for k in range(j, 4)) for j in range(4)]
    d = [v * Fraction(2) ** (u_shift * j) for j, v in enumerate(shifted)]  # coefficients of u^j, accel LSB
    for frac in range(40, -1, -1):
        coeffs = [round_half_away(v * Fraction(2) ** frac) for v in d]
        bound = sum(abs(c) for c in coeffs) + 3
        if max(abs(c) for c in coeffs) <= INT32_MAX and bound << u_shift < INT64_SAFE:
            return QPoly3(spec.method, limits, lo, hi, t_ref, u_shift, tuple(coeffs), frac, bound)
    raise UserError("poly3: coefficients too large for the fixed-point format")


def quantise_checkpoint(ckpt: Checkpoint, *, accel_limit_g: float = DEFAULT_ACCEL_LIMIT_G) -> QuantModel:
    """The fixed-point model of a parsed checkpoint (deterministic: same input, same integers)."""
    limits = _limits(ckpt, accel_limit_g)
    model = ckpt.model
    if isinstance(model, DlstmSpec | PersistenceSpec):
        return _stream(model, limits)
    if isinstance(model, PlaSpec):
        return _pla(model, limits)
    return _poly3(model, limits)
