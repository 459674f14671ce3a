"""The stream family's quantiser: float specs -> the fixed-point front end, network and head.

The formats of the streaming network are declared once in :mod:`codegen.qformats` (which also
writes them into the C kernel library); the shared ones (acceleration, temperature) in
:mod:`codegen.quantize`. All scales are powers of two except the normalisation multipliers.

=====================  ===========  ======================================================
quantity               storage      format
=====================  ===========  ======================================================
window sums            int64        exact: a running sum from the window's start phase, plus one
                                    sum per decimation period when the window is longer
window means           int64        Q24 of the input unit (fewer bits only when W * range needs it)
network inputs x       int16        Q3.12 (+-8 standard deviations) or wider, down to Q5.10 (+-32),
                                    when it costs layer 0 no accumulator bit; clamping is flagged
weights                int16        per layer: Q(A - x frac) per layer-0 input, Q(A - 15) for h
biases, accumulators   int32        Q(A), one per gate row; |b| + sum |w| |v| < 2**31 proved
gates i, f, o          Q16          table sigmoid, 1 .. 65535
g, tanh(c)             Q15          table tanh, -32767 .. 32767
hidden state h         int16        Q15
cell state c           int32        Q7.24, saturated at the int32 limits (flagged)
head                   int32/int64  weights in accel LSB per unit of h, Q(f); bias, accumulator Q(f+15)
held estimate          int64        Q16 accel LSB, saturated at +-(2**31 - 1) LSB (flagged)
=====================  ===========  ======================================================

A layer's accumulator format Q(A) is the largest A (16 .. 30) such that every weight fits int16
*and* the worst case of every row, ``|b_q| + sum_j |w_q| * 32767``, stays below 2**31: the int32
multiply-accumulates (two per SMLAD on a Cortex-M4) can then never overflow, which is proved here,
not hoped for. Both matrices of a layer share the accumulator (each layer-0 input column has
its own weight format, Q(A - 12) .. Q(A - 10); h's weights are Q(A - 15)). The accumulator indexes the activation table directly
(no rounding step): the gate rows read it with shift A - 4 (tanh) or A - 3 (sigmoid).

Why 16 bits: the budget (docs/codegen.md) is golden minus float at most 1e-3 mg RMS and 5e-3 mg
maximum on the 2 h validation run, 300 times below the sensor's 0.354 mg noise; 16-bit operands
meet it with a margin and run in a quarter of the instructions of the former int32 x int32 -> int64
network (int32 weights had errors near 1e-7 mg: 10,000 times below the noise).

Why the window mean is Q24: the temperature model's rate input differentiates two 5 s means 1 s
apart, and Q8 cost 0.13 ug RMS there. A fine mean unit is shifted right (``pre_shift``, rounding)
before the normalisation multiply so that the multiplier keeps 31 significant bits in int64.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from codegen.activations import ACT_ERROR_LSB, T_MAX, sigmoid_q16, tanh_q15
from codegen.families.stream.spec import DlstmModelSpec, FrontEndSpec, PersistenceSpec
from codegen.fixedpoint import (
    INT16_MAX,
    INT32_MAX,
    INT64_MAX,
    headroom_bits,
    quantise_array,
    round_half_away,
)
from codegen.qformats import (
    ACT_STEP_BITS,
    EST_FRAC,
    GATE_FRAC,
    H_FRAC,
    H_MAX,
    MAX_ACC_FRAC,
    MIN_ACC_FRAC,
    TANH_FRAC,
    X_FRAC,
    X_MAX,
    X_MIN_FRAC,
)
from codegen.quantize import ACCEL_PER_MG, INT64_SAFE, Limits
from codegen.step_units import STEP_UNITS
from trainer.errors import UserError

EST_LIMIT = INT32_MAX << EST_FRAC  # the estimate saturates at +-(2**31 - 1) LSB (flagged)
MAX_WINDOW_SAMPLES = 0xFFFF  # tdck_rdiv_round64 divides by fewer than 2**16 samples (32-bit divisions)
MAX_MEAN_FRAC = 24  # window means: Q24 of the input unit when the window allows (the rate input needs it)
MAX_HEAD_FRAC = 45  # head weights' fractional bits when they are tiny
X_SLOTS = 2  # the network inputs take two int16 slots of the state vector (one pair)
# When a DLSTM's network step runs: all on the sample that ends its window ("step"), or split into
# tasks spread over the samples of the decimation period ("spread": no sample costs much more than
# the average; the estimate then takes effect D - 1 samples later; docs/codegen.md "Schedules").
SCHEDULES = ("step", "spread")
# The spread schedule's tasks per LSTM unit: the first pairs of its dot product, the other pairs, its
# gates' activations, its cell (each small enough that one per sample keeps the worst sample under
# twice the average).
UNIT_TASKS = ("dot", "dot_rest", "gates", "cell")


@dataclass(frozen=True)
class QMatrix:
    """A weight matrix (int16 in the layers, int32 in the head), its fractional bits, and its share of
    the accumulator bound."""

    q: np.ndarray  # int64 values within int32
    frac: int
    input_max: int  # largest |input_q| it multiplies
    input_frac: int

    @property
    def row_bounds(self) -> np.ndarray:
        """Worst-case |sum_j w_q x_q| of each row (Python ints: exact)."""
        return np.array([sum(abs(int(v)) for v in row) * self.input_max for row in np.atleast_2d(self.q)])

    @property
    def acc_bound(self) -> int:
        return int(np.max(self.row_bounds, initial=0))


@dataclass(frozen=True)
class QInput:
    """``x_q = clamp(rshift_round(clamp(rshift_round(v - mu_q, pre_shift), +-d_max) * inv_q, shift), +-X_MAX)``.

    ``d_max`` is where x saturates anyway; clamping there first keeps the product inside int64
    whatever the scale, without changing any result.
    """

    name: str
    mu_q: int
    pre_shift: int
    inv_q: int
    shift: int
    d_max: int
    mean: float
    std: float
    unit: str
    frac: int  # x_q is Q(frac): X_FRAC, or wider down to X_MIN_FRAC when layer 0 loses no bit

    @property
    def product_headroom(self) -> float:
        return headroom_bits(self.d_max * self.inv_q, INT64_MAX)


@dataclass(frozen=True)
class QLayer:
    """One LSTM layer: per gate row ``acc = b + W v`` in int32 Q(acc_frac), v = (input, own h).

    ``w_padded`` holds both matrices in the columns of the layer's slice of the state vector
    (``vec[offset : offset + 2 * pairs]``: the inputs padded to a pair, then h), zeros at the
    padding; the C kernel reads it interleaved per unit (:meth:`kernel_weights`).
    """

    wx: QMatrix
    wh: QMatrix
    b: np.ndarray  # int64 values within int32, Q(acc_frac): the accumulators' initial values
    w_padded: np.ndarray  # (4H, 2 pairs) int64 values within int16
    offset: int  # first slot of the layer's input in the state vector
    acc_frac: int
    acc_bound: int  # worst-case |accumulator| over the rows, Q(acc_frac), < 2**31
    z_bound: float  # worst-case |pre-activation| (real)
    cell_bound: float  # worst-case |c| (real units) from the gate bounds
    forget_max_q: int  # Q16

    @property
    def hidden_size(self) -> int:
        return self.wh.q.shape[1]

    @property
    def pairs(self) -> int:
        return self.w_padded.shape[1] // 2

    @property
    def first_pairs(self) -> int:
        """Spread schedule: the pairs of the dot product's first task (the rest, at least one, follow)."""
        return (self.pairs + 1) // 2

    @property
    def shift(self) -> int:
        """The gate rows' activation shift: tanh reads acc / 2**(shift + 4), sigmoid one bit more."""
        return self.acc_frac - ACT_STEP_BITS

    @property
    def acc_headroom(self) -> float:
        return headroom_bits(self.acc_bound, INT32_MAX)

    def kernel_weights(self) -> np.ndarray:
        """The C's stream of int32 words, unit by unit: the unit's 4 biases (rows i, f, g, o) with the
        sign bit flipped (``b + 2**31`` mod 2**32 read as int32: the C accumulates in excess-2**31
        form, so the activation's segment is one unsigned shift), then the packed pairs
        ``w[p][r] = hi 2**16 + (lo mod 2**16)`` with ``lo, hi = w_padded[r H + j][2p], [2p + 1]``."""
        H = self.hidden_size
        blocks = self.w_padded.reshape(4, H, self.pairs, 2).transpose(1, 2, 0, 3)  # [j][p][r][e]
        packed = (blocks[..., 1] * 65536 + (blocks[..., 0] & 0xFFFF)).reshape(H, 4 * self.pairs)
        b = self.b.reshape(4, H).T  # [j][r]
        flipped = np.where(b >= 0, b - 2**31, b + 2**31)
        return np.concatenate((flipped, packed), axis=1)


@dataclass(frozen=True)
class QHead:
    w: QMatrix  # (1, H), accel LSB per unit of h
    shift: int  # frac + 15
    bias_q: int  # int64, Q(shift) accel LSB (head bias * std + mean): the accumulator's initial value
    acc_bound: int  # worst-case |accumulator|
    estimate_bound: float  # accel LSB

    @property
    def may_saturate(self) -> bool:
        """Whether the rounded estimate (Q(EST_FRAC)) can reach EST_LIMIT: rounding is monotone, so
        the accumulator's bound rounded the same way bounds it; when it cannot, the C omits the clamp."""
        s = self.shift - EST_FRAC
        estimate_q_bound = (self.acc_bound + ((1 << s) >> 1)) >> s
        return estimate_q_bound > EST_LIMIT


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
    mean_frac: int  # the window mean is Q(mean_frac) of the input unit (network models)
    schedule: str = "step"  # one of SCHEDULES

    @property
    def window(self) -> int:
        fe = self.frontend
        return fe.temp_window if self.kind == "temperature" else fe.accel_window

    @property
    def hidden_size(self) -> int:
        return self.layers[0].hidden_size if self.layers else 0

    @property
    def hidden_slots(self) -> int:
        """Slots of one layer's h in the state vector: H padded to a pair."""
        return self.hidden_size + self.hidden_size % 2

    @property
    def vector_slots(self) -> int:
        return X_SLOTS + len(self.layers) * self.hidden_slots if self.layers else 0

    @property
    def chunks(self) -> int:
        """Completed decimation periods the window needs besides the running sum: (W - 1) div D."""
        return (self.window - 1) // self.frontend.decimation

    @property
    def chunk_start(self) -> int:
        """The phase at which the running sum restarts: (1 - W) mod D."""
        return (1 - self.window) % self.frontend.decimation

    @property
    def full_steps(self) -> int:
        """From this network step on the window is full: ceil((W - 1) / D)."""
        return -(-(self.window - 1) // self.frontend.decimation)

    @property
    def tasks(self) -> int:
        """Spread schedule: the network step's tasks: one per input (its normalisation), UNIT_TASKS
        per unit, then the head."""
        return len(self.inputs) + len(UNIT_TASKS) * len(self.layers) * self.hidden_size + 1

    @property
    def latency_samples(self) -> int:
        """Samples by which the spread schedule delays the estimate (0 for "step")."""
        return self.frontend.decimation - 1 if self.schedule == "spread" else 0

    def tasks_before(self, phase: int) -> int:
        """Spread schedule: tasks done in the phases before ``phase`` (0 .. D), evenly spread."""
        return phase * self.tasks // self.frontend.decimation

    def macs_per_step(self) -> int:
        """Multiply-accumulates of one network step (the lower bound of its cost)."""
        total = sum(layer.wx.q.size + layer.wh.q.size for layer in self.layers)
        return total + (self.head.w.q.size if self.head else 0)


def _fits_int32(q: np.ndarray) -> bool:
    return int(np.max(np.abs(q), initial=0)) <= INT32_MAX


def _quantise_or_none(values: np.ndarray, frac: int) -> np.ndarray | None:
    """``quantise_array``, or None when a value does not fit int64 at this scale."""
    try:
        return quantise_array(values, frac)
    except ValueError:
        return None


def _ceil_shift(value: int, shift: int) -> int:
    """An upper bound of |rshift_round(x, shift)| for |x| <= value."""
    return (value + (1 << shift) - 1) >> shift if shift else value


def _fits_int16(q: np.ndarray) -> bool:
    return int(np.max(np.abs(q), initial=0)) <= INT16_MAX


def _gate_max(z_max: np.ndarray, kind: str) -> np.ndarray:
    """Largest integer gate (Q16 sigmoid or Q15 tanh) for |z| <= z_max, with the table's error."""
    z_q = np.minimum(np.ceil(z_max * 2.0**MIN_ACC_FRAC), INT32_MAX).astype(np.int64)
    shift = MIN_ACC_FRAC - ACT_STEP_BITS
    if kind == "sigmoid":
        return np.minimum(sigmoid_q16(z_q, shift) + ACT_ERROR_LSB, T_MAX)
    return np.minimum(tanh_q15(z_q, shift) + ACT_ERROR_LSB, (1 << TANH_FRAC) - 1)


def _layer(
    spec_w_x: np.ndarray,
    spec_w_h: np.ndarray,
    spec_b: np.ndarray,
    index: int,
    hidden_slots: int,
    input_fracs: tuple[int, ...],
) -> QLayer:
    """``input_fracs``: the Q format of each input of the layer (layer 0: per network input)."""
    in_frac = max(input_fracs)
    w_x = np.atleast_2d(np.asarray(spec_w_x, dtype=np.float64))
    w_h = np.atleast_2d(np.asarray(spec_w_h, dtype=np.float64))
    b = np.asarray(spec_b, dtype=np.float64)
    for acc_frac in range(MAX_ACC_FRAC, MIN_ACC_FRAC - 1, -1):  # the largest A that fits
        columns = [_quantise_or_none(w_x[:, k], acc_frac - f) for k, f in enumerate(input_fracs)]
        qx = None if any(c is None for c in columns) else np.stack(columns, axis=1)  # type: ignore[arg-type]
        qh = _quantise_or_none(w_h, acc_frac - H_FRAC)
        b_q = _quantise_or_none(b, acc_frac)
        if qx is None or qh is None or b_q is None or not (_fits_int16(qx) and _fits_int16(qh)):
            continue
        wx = QMatrix(
            qx, acc_frac - in_frac, X_MAX if index == 0 else H_MAX, in_frac
        )  # frac: the finest column
        wh = QMatrix(qh, acc_frac - H_FRAC, H_MAX, H_FRAC)
        rows = [
            int(rx) + int(rh) + abs(int(bb))
            for rx, rh, bb in zip(wx.row_bounds, wh.row_bounds, b_q, strict=True)
        ]
        bound = max(rows, default=0)
        if bound <= INT32_MAX:
            break
    else:
        real = np.sum(np.abs(w_x), axis=1) * 16.0 + np.sum(np.abs(w_h), axis=1) + np.abs(b)
        raise UserError(
            f"layer {index}: weights too large for int16 with a safe int32 accumulator of at least "
            f"{MIN_ACC_FRAC} fractional bits (largest row sum of 16 |w_x| + |w_h| + |b| = {float(np.max(real)):.4g})"
        )
    H = wh.q.shape[1]
    n_in = wx.q.shape[1]
    in_slots = X_SLOTS if index == 0 else hidden_slots
    padded = np.zeros((4 * H, in_slots + hidden_slots), dtype=np.int64)
    padded[:, :n_in] = wx.q
    padded[:, in_slots : in_slots + H] = wh.q
    offset = 0 if index == 0 else X_SLOTS + (index - 1) * hidden_slots
    z_real = np.asarray(rows, dtype=np.float64) / 2.0**acc_frac
    i_max = _gate_max(z_real[0:H], "sigmoid") / 2.0**GATE_FRAC
    f_max_q = _gate_max(z_real[H : 2 * H], "sigmoid")
    g_max = _gate_max(z_real[2 * H : 3 * H], "tanh") / 2.0**TANH_FRAC
    # |c'| <= f |c| + i |g| + 2**-25 (one rounding) -> geometric bound; f <= 1 - 2**-16 always.
    cell = (i_max * g_max + 2.0**-25) / (1.0 - f_max_q / 2.0**GATE_FRAC)
    return QLayer(
        wx,
        wh,
        b_q,
        padded,
        offset,
        acc_frac,
        bound,
        float(np.max(z_real, initial=0.0)),
        float(np.max(cell, initial=0.0)),
        int(np.max(f_max_q, initial=0)),
    )


def _input(
    name: str, v_max: int, unit_per_lsb: Fraction, mean: float, std: float, unit: str, frac: int = X_FRAC
) -> QInput:
    mu_q = round_half_away(Fraction(mean) / unit_per_lsb)
    if abs(mu_q) >= INT64_SAFE // 2:
        raise UserError(f"input '{name}': mean {mean:g} {unit} is far outside the input range")
    gain = unit_per_lsb / Fraction(std) * (1 << frac)  # x_q per LSB of v
    # inv_q gets 31 significant bits: the product d_max * inv_q is then about 2**(31 + shift), so
    # shift <= 30 keeps it in int64; a fine input unit (gain < 1) is first shifted right by
    # pre_shift (rounding), which costs nothing measurable and leaves inv_q its 31 bits.
    wanted = 30 - math.floor(math.log2(gain))
    pre_shift, shift = max(0, wanted - 30), min(30, max(0, wanted))
    gain_d = gain * (1 << pre_shift)  # x_q per LSB of d
    v_span = _ceil_shift(v_max + abs(mu_q), pre_shift)
    while shift >= 0:
        inv_q = round_half_away(gain_d * (1 << shift))
        if inv_q < 1:
            break
        saturating = -(-(X_MAX + 1) * (1 << shift) // inv_q)  # ceil: from here on x clamps anyway
        d_max = min(v_span, saturating)
        if d_max * inv_q < INT64_SAFE:
            return QInput(name, mu_q, pre_shift, inv_q, shift, d_max, mean, std, unit, frac)
        shift -= 1
    raise UserError(f"input '{name}': mean {mean:g} / std {std:g} {unit} cannot be scaled in int64")


def _head(spec: DlstmModelSpec, unit: str = "mg") -> QHead:
    """``estimate = rshift_round(bias_q + sum_j w_q h_q, f + 15)``: y * std + mean folded in, int64
    (``unit``: the channel's, which the mean and std are in)."""
    fe = spec.frontend
    label = STEP_UNITS[unit].label
    scale = Fraction(fe.output_std) * ACCEL_PER_MG  # accel LSB per unit of y
    w_real = np.asarray(spec.head_w, dtype=np.float64) * float(scale)
    bias = (Fraction(spec.head_b) * Fraction(fe.output_std) + Fraction(fe.output_mean)) * ACCEL_PER_MG
    for frac in range(MAX_HEAD_FRAC, EST_FRAC - H_FRAC - 1, -1):
        q = _quantise_or_none(w_real[None, :], frac)
        if q is None or not _fits_int32(q):
            continue
        w = QMatrix(q, frac, H_MAX, H_FRAC)
        bias_q = round_half_away(bias * Fraction(2) ** (frac + H_FRAC))
        acc_bound = w.acc_bound + abs(bias_q)
        if acc_bound < INT64_SAFE:
            return QHead(w, frac + H_FRAC, bias_q, acc_bound, acc_bound / 2.0 ** (frac + H_FRAC))
    raise UserError(
        f"head: output mean {fe.output_mean:g} {label} / std {fe.output_std:g} {label} cannot be represented"
    )


def _mean_frac(window: int, v_max: int) -> int:
    """Fractional bits of the window mean: up to 24, as long as sum * 2**F stays below 2**62."""
    frac = MAX_MEAN_FRAC
    while frac > 0 and window * v_max << frac >= INT64_SAFE:
        frac -= 1
    return frac


def quantise_stream(
    spec: DlstmModelSpec | PersistenceSpec, limits: Limits, schedule: str = "step"
) -> QStream:
    """The fixed-point model (``schedule``: one of :data:`SCHEDULES`; persistence only steps)."""
    fe = spec.frontend
    used = (
        "temp_window" if not isinstance(spec, PersistenceSpec) and fe.kind != "recursive" else "accel_window"
    )
    if getattr(fe, used) > MAX_WINDOW_SAMPLES:
        raise UserError(
            f"frontend.{used}: {getattr(fe, used)} samples; the C module averages at most "
            f"{MAX_WINDOW_SAMPLES} (shorten the window or export at a lower --rate)"
        )
    if isinstance(spec, PersistenceSpec):  # the estimate is the mean itself, held in Q16
        frac = min(EST_FRAC, _mean_frac(fe.accel_window, limits.signal_lsb))
        return QStream(spec.method, "recursive", fe, limits, (), (), None, frac, schedule)
    # (name, largest |v| in mean LSB, unit per LSB, mean, std, unit) of each network input
    features: list[tuple[str, int, Fraction, float, float, str]]
    if fe.kind == "recursive":
        step = STEP_UNITS[limits.unit]
        frac = _mean_frac(fe.accel_window, limits.signal_lsb)
        mean_lsb = 1 << frac
        features = [
            # the raw input's window mean, in the channel's unit (mg, deg/s, Pa)
            (
                step.signal,
                limits.signal_lsb * mean_lsb,
                Fraction(1, ACCEL_PER_MG * mean_lsb),
                0.0,
                0.0,
                step.label,
            ),
        ]
    else:
        t_max = max(-limits.temp_lo_mdegc, limits.temp_hi_mdegc)
        span = limits.temp_hi_mdegc - limits.temp_lo_mdegc
        frac = _mean_frac(fe.temp_window, t_max)
        mean_lsb = 1 << frac
        rate_unit = (
            Fraction(60) * Fraction(fe.rate_hz) / (fe.decimation * 1000 * mean_lsb)
        )  # degC/min per LSB
        features = [
            ("temp", t_max * mean_lsb, Fraction(1, 1000 * mean_lsb), 0.0, 0.0, "degC"),
            ("rate", span * mean_lsb, rate_unit, 0.0, 0.0, "degC/min"),
        ]
    features = [
        (name, v_max, unit_lsb, fe.inputs_mean[k], fe.inputs_std[k], unit)
        for k, (name, v_max, unit_lsb, _, _, unit) in enumerate(features)
    ]
    hidden = spec.layers[0].w_h.shape[1] if spec.layers else 0
    slots = hidden + hidden % 2

    def first_layer(fracs: list[int]) -> QLayer:
        layer = spec.layers[0]
        return _layer(layer.w_x, layer.w_h, layer.b, 0, slots, tuple(fracs))

    # A difference of means (the rate input) is heavy-tailed (the first steps after a reset, sensor
    # noise): clamped at +-8 sigma it cost a trained dlstm-temp 0.07 mg. It gets the widest range
    # (down to Q10: +-32 sigma) that costs layer 0 no accumulator bit. Levels keep Q12: a wider
    # format costs them resolution (6e-4 instead of 4e-4 mg RMS) and they stay within +-8 sigma.
    fracs = [X_FRAC] * len(features)
    base = first_layer(fracs).acc_frac
    for k in [k for k, feature in enumerate(features) if feature[0] == "rate"]:
        for wider in range(X_FRAC - 1, X_MIN_FRAC - 1, -1):
            trial = [*fracs[:k], wider, *fracs[k + 1 :]]
            try:
                if first_layer(trial).acc_frac < base:
                    break
            except UserError:
                break
            fracs = trial
    inputs = tuple(_input(*feature, frac=f) for feature, f in zip(features, fracs, strict=True))
    layers = tuple(
        _layer(layer.w_x, layer.w_h, layer.b, k, slots, tuple(fracs) if k == 0 else (H_FRAC,) * hidden)
        for k, layer in enumerate(spec.layers)
    )
    return QStream(spec.method, fe.kind, fe, limits, inputs, layers, _head(spec, limits.unit), frac, schedule)
