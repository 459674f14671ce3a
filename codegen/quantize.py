"""Float specs -> fixed-point models, with every scale, shift and worst-case bound decided offline.

The formats of the streaming network are declared once in :mod:`codegen.qformats` (which also
writes them into the C kernel library); the memoryless models keep their own (below). All scales
are powers of two except the normalisation multipliers.

=====================  ===========  ======================================================
quantity               storage      format
=====================  ===========  ======================================================
acceleration in/out    int32        Q4 micro-g: 1 LSB = 1/16 ug (62.5 ng), range +-134 g
temperature in         int32        milli-degC
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
PLA slopes/intercepts  int32/int64  accel LSB per mdegC and accel LSB, Q(f_pla)
cubic coefficients     int32        accel LSB, of u^k with u = (T - T_ref) / 2**p, Q(f_poly)
physics temperatures   int32        Q(tf) mdegC about the range's centre (play operator), see :func:`_physics`
physics filter states  int64        Q(tf + 32) mdegC: the high word is the int32 temperature
physics coefficients   int32        filters Q(32 + s); cubic d_k Q(f + k); drift accumulator int64 Q(f + 32)
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

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from codegen.activations import ACT_ERROR_LSB, T_MAX, sigmoid_q16, tanh_q15
from codegen.family import QuantModel, family_of
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
from codegen.spec import (
    Checkpoint,
    DlstmModelSpec,
    FrontEndSpec,
    PersistenceSpec,
    PhysicsSpec,
)
from trainer.errors import UserError
from trainer.physics.catalogue.streamed import STREAMED, c_options, c_terms
from trainer.physics.catalogue.streaming import CHAIN, FixedPoint

EST_LIMIT = INT32_MAX << EST_FRAC  # the estimate saturates at +-(2**31 - 1) LSB (flagged)
MAX_WINDOW_SAMPLES = 0xFFFF  # tdck_rdiv_round64 divides by fewer than 2**16 samples (32-bit divisions)
MAX_MEAN_FRAC = 24  # window means: Q24 of the input unit when the window allows (the rate input needs it)
ACCEL_FRAC = 4  # the step API's acceleration unit is 2**-4 ug
ACCEL_PER_MG = 1000 << ACCEL_FRAC
MAX_HEAD_FRAC = 45  # head weights' fractional bits when they are tiny
X_SLOTS = 2  # the network inputs take two int16 slots of the state vector (one pair)
INT64_SAFE = 1 << 62  # every int64 intermediate stays below this (one bit of margin)
DEFAULT_ACCEL_LIMIT_G = 16.0
MAX_ACCEL_LIMIT_G = 128.0  # 128 g * 16e6 LSB/g < 2**31
# When a DLSTM's network step runs: all on the sample that ends its window ("step"), or split into
# tasks spread over the samples of the decimation period ("spread": no sample costs much more than
# the average; the estimate then takes effect D - 1 samples later; docs/codegen.md "Schedules").
SCHEDULES = ("step", "spread")
# The spread schedule's tasks per LSTM unit: the first pairs of its dot product, the other pairs, its
# gates' activations, its cell (each small enough that one per sample keeps the worst sample under
# twice the average).
UNIT_TASKS = ("dot", "dot_rest", "gates", "cell")
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


@dataclass(frozen=True)
class QLowpass:
    """The exact first-order-hold low-pass ``y' = a y + b0 x + b1 x_prev`` as ``tdcp_lowpass``::

        y += floor((x_prev 2^32 - y) / 2^(32 + shift)) c_q + (T - T_prev) 2^(tf - shift) b_q

    with ``c_q = round((1 - a) 2^(32 + shift))``, ``b_q = round(b0 2^(32 + shift))`` (int32) and the
    state int64 Q(tf + 32) mdegC about the centre (its high word is the Q(tf) temperature)."""

    name: str
    tau_s: float
    c_q: int
    b_q: int
    shift: int
    c_real: float  # 1 - a, exactly the float model's
    b0_real: float
    error_mdegc: float  # bound of |state - the float model's state| (floors and coefficient rounding)
    sensitivity_mg_per_c: float  # how much the drift moves per degC of this state

    @property
    def error_mg(self) -> float:
        return self.error_mdegc * self.sensitivity_mg_per_c / 1000.0


@dataclass(frozen=True)
class QGain:
    """A drift term ``gain (difference)``: an int32 difference in Q(tf) mdegC times the int32 ``q``,
    added to the int64 drift accumulator in Q(frac + 32) accel LSB (one SMLAL)."""

    name: str
    q: int
    diff_bound: int  # |difference|, Q(tf) mdegC
    bound: int  # |difference q|, Q(frac + 32) accel LSB


@dataclass(frozen=True)
class QTerm:
    """One streamed effect of a :class:`QPhysics` in integers (its ``FixedPoint`` says what they mean)."""

    identifier: str
    filter: QLowpass | None
    gain: QGain | None
    margin_q: int | None  # an int32 temperature offset (the play's half width), Q(tf) mdegC

    @property
    def fixed(self) -> FixedPoint:
        fixed = STREAMED[self.identifier].fixed
        assert fixed is not None
        return fixed


@dataclass(frozen=True)
class QPhysics:
    """The grey-box model in int32 temperatures and products (see :func:`_physics`)."""

    method: str
    limits: Limits
    rate_hz: float
    clip_lo_mdegc: int
    clip_hi_mdegc: int
    centre_mdegc: int  # temperatures are x = (T - centre) 2^temp_frac
    temp_frac: int  # tf: int32 temperatures Q(tf) mdegC; filter states int64 Q(tf + 32)
    terms: tuple[QTerm, ...]  # the streamed effects the export carries, in step order
    t_ref_mdegc: int  # the catalogue's polynomial reference (re-expanded about the centre)
    u_shift: int  # Horner argument u = T_b 2^u_shift, |u| < 2^31, read as U = u / 2^31
    coefficients_q: tuple[int, ...]  # d0..d3: d_k of U^k in Q(frac + k) accel LSB, int32
    horner_bounds: tuple[int, ...]  # |p_0| .. |p_3| of the Horner steps, each < 2^31
    frac: int  # the polynomial's value is Q(frac) accel LSB; the accumulator Q(frac + 32)
    bound: int  # |drift accumulator|, Q(frac + 32), < 2^62
    tag: int  # uint32 identifying these constants (a saved state is restored only by its own model)

    @property
    def filters(self) -> tuple[QLowpass, ...]:
        return tuple(t.filter for t in self.terms if t.filter is not None)

    @property
    def gains(self) -> tuple[QGain, ...]:
        return tuple(t.gain for t in self.terms if t.gain is not None)

    @property
    def options(self) -> tuple[str, ...]:
        """The option bits its terms set (what the polynomial reads)."""
        return tuple(t.fixed.option for t in self.terms if t.fixed.option is not None)

    @property
    def poly_reads(self) -> str | None:
        """The state word the polynomial reads instead of T_pm (None: T_pm)."""
        return next((t.fixed.poly_reads for t in self.terms if t.fixed.poly_reads is not None), None)


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


def _head(spec: DlstmModelSpec) -> QHead:
    """``estimate = rshift_round(bias_q + sum_j w_q h_q, f + 15)``: y * std + mean folded in, int64."""
    fe = spec.frontend
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
        f"head: output mean {fe.output_mean:g} mg / std {fe.output_std:g} mg cannot be represented"
    )


def _limits(ckpt: Checkpoint, accel_limit_g: float) -> Limits:
    if not (math.isfinite(accel_limit_g) and 0 < accel_limit_g <= MAX_ACCEL_LIMIT_G):
        raise UserError(f"--accel-limit-g must be in (0, {MAX_ACCEL_LIMIT_G:g}] g, got {accel_limit_g!r}")
    lo, hi = ckpt.valid_temp_range_c
    clamp_c = [limit / 1000 for limit in TEMP_LIMITS_MDEGC]
    if not clamp_c[0] <= lo <= hi <= clamp_c[1]:
        raise UserError(
            f"checkpoint field 'valid_temp_range_c' {lo:g} .. {hi:g} degC is outside the {clamp_c[0]:g} .. "
            f"{clamp_c[1]:g} degC the module clamps its temperature to, so its out-of-range flag could never "
            f"fire: a model fitted on impossible temperatures; re-fit on a recording without them"
        )
    clip = (-(1 << 31) + 1, INT32_MAX)
    valid_lo = min(max(math.ceil(Fraction(lo) * 1000), clip[0]), clip[1])
    valid_hi = min(max(math.floor(Fraction(hi) * 1000), clip[0]), clip[1])
    return Limits(
        round(accel_limit_g * 1000 * ACCEL_PER_MG), valid_lo_mdegc=valid_lo, valid_hi_mdegc=valid_hi
    )


def _mean_frac(window: int, v_max: int) -> int:
    """Fractional bits of the window mean: up to 24, as long as sum * 2**F stays below 2**62."""
    frac = MAX_MEAN_FRAC
    while frac > 0 and window * v_max << frac >= INT64_SAFE:
        frac -= 1
    return frac


def quantise_stream(spec: DlstmModelSpec | PersistenceSpec, limits: Limits) -> QStream:
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
        frac = min(EST_FRAC, _mean_frac(fe.accel_window, limits.accel))
        return QStream(spec.method, "recursive", fe, limits, (), (), None, frac)
    # (name, largest |v| in mean LSB, unit per LSB, mean, std, unit) of each network input
    features: list[tuple[str, int, Fraction, float, float, str]]
    if fe.kind == "recursive":
        frac = _mean_frac(fe.accel_window, limits.accel)
        mean_lsb = 1 << frac
        features = [
            ("accel", limits.accel * mean_lsb, Fraction(1, ACCEL_PER_MG * mean_lsb), 0.0, 0.0, "mg"),
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
    return QStream(spec.method, fe.kind, fe, limits, inputs, layers, _head(spec), frac)


HI_BITS = 32  # a filter state's high word is its int32 temperature (tdcp_hi)
MAX_TEMP_FRAC = 24  # finer int32 temperatures buy nothing (the filters' floors are bounded below)
MAX_DRIFT_FRAC = 30
PHYS_FILTER_BUDGET_MG = 3e-4  # per filter (at most three): their sum stays under the 1e-3 mg budget


def _lowpass(
    name: str, tau_s: float, rate_hz: float, tf: int, reach: int, span: int, sensitivity: float
) -> QLowpass:
    """The filter's coefficients at the shift that minimises the bound of its state's error.

    Per step the floor of the difference costs less than 2^(shift - tf) mdegC times c, and the
    rounded coefficients |dc| |x_prev - y| + |db| |x - x_prev|; through the filter (gain 1 / c) the
    state stays within ``error_mdegc`` of the float model's, plus 2^-tf for reading its high word. A
    larger shift gives c more bits and the difference fewer: the generator takes the best."""
    from trainer.physics.thermal import lowpass_coefficients

    (b0_arr, _), (_, minus_a) = lowpass_coefficients(tau_s, 1.0 / rate_hz)
    c, b0 = Fraction(1) + Fraction(float(minus_a)), Fraction(float(b0_arr))
    if not (0 < b0 <= c < Fraction(1, 2)):
        raise UserError(
            f"physics: {name} filter (tau {tau_s:g} s) is too short for {rate_hz:g} Hz (or too long): "
            f"1 - a = {float(c):.3g} must lie in (0, 1/2)"
        )
    best: tuple[Fraction, int, int, int] | None = None
    for shift in range(0, min(tf, 30) + 1):
        scale = Fraction(2) ** (HI_BITS + shift)
        c_q, b_q = round_half_away(c * scale), round_half_away(b0 * scale)
        if c_q + b_q > INT32_MAX:
            break
        if not 0 < b_q <= c_q:
            continue
        dc, db = abs(Fraction(c_q) / scale - c), abs(Fraction(b_q) / scale - b0)
        error = Fraction(2) ** (shift - tf) + Fraction(1, 2**tf) + (2 * reach * dc + span * db) / c
        if best is None or error < best[0]:
            best = (error, shift, c_q, b_q)
    if best is None:
        raise UserError(f"physics: {name} filter (tau {tau_s:g} s at {rate_hz:g} Hz) cannot be represented")
    error, shift, c_q, b_q = best
    # tdcp_lowpass's preconditions: |x_prev 2^32| + |y| < 2^63 and |y| + |d c| + |step b0| < 2^63
    y_max, d_max = reach << (tf + HI_BITS), ((2 * reach) << (tf - shift)) + 1
    if 2 * y_max > INT64_MAX or y_max + d_max * c_q + (span << (tf - shift)) * b_q > INT64_MAX:
        raise UserError(f"physics: {name} filter (tau {tau_s:g} s) cannot be represented in int64")
    q = QLowpass(name, tau_s, c_q, b_q, shift, float(c), float(b0), float(error), sensitivity)
    if error > 1 or q.error_mg > PHYS_FILTER_BUDGET_MG:
        raise UserError(
            f"physics: {name} filter (tau {tau_s:g} s at {rate_hz:g} Hz) would stray {float(error):.3g} mdegC "
            f"from the float model, {q.error_mg:.3g} mg of drift (budget {PHYS_FILTER_BUDGET_MG:g} mg)"
        )
    return q


def _horner_bounds(d: list[int]) -> list[int]:
    """|p_k| of ``p_3 = d_3, p_k = d_k + floor(p_(k+1) u / 2^32 + 1/2)`` for any |u| < 2^31."""
    bounds = [abs(d[3])]
    for k in (2, 1, 0):
        bounds.insert(0, abs(d[k]) + (bounds[0] + 1) // 2)
    return bounds


def quantise_physics(spec: PhysicsSpec, limits: Limits) -> QPhysics:
    """int32 temperatures, int64 filter states, int32 x int32 products (tdc_physics_kernels.h).

    Temperatures are ``x = (T - centre) 2^tf`` mdegC about the training range's centre, ``tf`` the
    largest for which every temperature, difference and ``x +-`` a term's margin fits int32. The
    filters stay within the range (their updates are convex combinations; the floors move them down
    by less than 1 mdegC), so the states are bounded by the range too. The cubic is re-expanded
    exactly about the centre in ``U = T_b 2^u_shift / 2^31`` and evaluated by Horner in int32 with
    rounded high-word products; the drift accumulator is int64 Q(frac + 32) accel LSB, ``frac`` the
    largest (<= 30) for which every Horner step, every gain and the sum fit (all proved here). What
    each streamed effect quantises is its ``FixedPoint`` (trainer/physics/catalogue)."""
    m = spec.model
    lo = round_half_away(Fraction(m.temp_range_c[0]) * 1000)
    hi = round_half_away(Fraction(m.temp_range_c[1]) * 1000)
    if not (-INT32_MAX <= lo < hi <= INT32_MAX) or hi - lo >= 1 << 20:
        raise UserError(
            f"physics: temperature range {m.temp_range_c} degC is outside the supported -524..524 degC"
        )
    span = hi - lo
    mid = (lo + hi) // 2
    # the centre: an immediate operand of one Thumb-2 instruction (12 bits, or 8 significant bits)
    grain = 1 if abs(mid) < 4096 else 1 << max(0, abs(mid).bit_length() - 8)
    centre = round_half_away(Fraction(mid, grain)) * grain
    reach = max(hi - centre, centre - lo) + 2  # |state - centre|, mdegC: the range and the floors' margin
    present: dict[str, tuple[str, FixedPoint, Mapping[str, float]]] = {}
    for term in m.terms:
        fixed = STREAMED[term.identifier].fixed
        if fixed is not None:
            present[fixed.name] = (term.identifier, fixed, term.params)
    margins: dict[str, tuple[Fraction, str]] = {}
    for name, (_, fixed, params) in present.items():
        if fixed.margin is not None:
            margins[name] = fixed.margin(params)
            if not margins[name][0] > 0:
                raise UserError(f"physics: {margins[name][1]} must be positive")
    tf = -1
    for k in range(MAX_TEMP_FRAC, -1, -1):
        h_q = max((round_half_away(half * 2**k) for half, _ in margins.values()), default=0)
        if (2 * reach) << k <= INT32_MAX and (reach << k) + h_q <= INT32_MAX:
            tf = k
            break
    if tf < 0:
        widest = max(margins.values(), key=lambda v: v[0])[1] if margins else "a margin"
        raise UserError(f"physics: {widest} is too wide for int32 temperatures")
    margin_q = {name: round_half_away(half * 2**tf) for name, (half, _) in margins.items()}
    from trainer.physics.catalogue.base import T_REF_C

    t_ref = round_half_away(Fraction(T_REF_C) * 1000)
    # drift sensitivity to each state (mg per degC), for the filters' error budget
    grid = np.linspace(lo / 1000, hi / 1000, 1001) - T_REF_C
    c1, c2, c3 = m.c_mg[1:]
    slope = float(np.max(np.abs(c1 + 2 * c2 * grid + 3 * c3 * grid**2)))
    gain_mg_per_c = {
        name: fixed.gain_mg_per_c(params)
        for name, (_, fixed, params) in present.items()
        if fixed.gain_mg_per_c is not None
    }
    proof_mass = slope + sum(
        fixed.proof_mass_weight * abs(gain_mg_per_c[name])
        for name, (_, fixed, _) in present.items()
        if fixed.proof_mass_weight
    )
    layout = _c_terms_of(present)
    filt: dict[str, QLowpass | None] = {}
    for fixed in layout:
        if fixed.tau_s is None:
            continue
        entry = present.get(fixed.name)
        if entry is None:
            filt[fixed.filter_name] = None
            continue
        chain = STREAMED[entry[0]].phase == CHAIN
        sensitivity = proof_mass if chain else abs(gain_mg_per_c[fixed.name])
        filt[fixed.filter_name] = _lowpass(
            fixed.filter_name, fixed.tau_s(entry[2]), spec.rate_hz, tf, reach, span, sensitivity
        )
    # the cubic about the centre, in U = T 2^(tf + u_shift) / 2^31 (T mdegC about the centre)
    u_shift = 0
    while (reach << (tf + u_shift + 1)) <= INT32_MAX:
        u_shift += 1
    delta = Fraction(centre) - Fraction(T_REF_C) * 1000
    e = [Fraction(c) * ACCEL_PER_MG / Fraction(1000) ** k for k, c in enumerate(m.c_mg)]
    about_centre = [sum(e[k] * math.comb(k, j) * delta ** (k - j) for k in range(j, 4)) for j in range(4)]
    unit = Fraction(2**31, 2 ** (tf + u_shift))  # mdegC per unit of U
    a = [v * unit**j for j, v in enumerate(about_centre)]  # accel LSB per U^j
    per_mdegc = Fraction(ACCEL_PER_MG, 1000)
    gain_terms = [fixed for fixed in layout if fixed.gain_mg_per_c is not None]
    for frac in range(MAX_DRIFT_FRAC, -1, -1):
        d = [round_half_away(v * Fraction(2) ** (frac + k)) for k, v in enumerate(a)]
        horner = _horner_bounds(d)
        if max(horner) > INT32_MAX:
            continue
        gains: dict[str, QGain | None] = {}
        for fixed in gain_terms:
            if fixed.name not in present:
                gains[fixed.name] = None
                continue
            diff_bound = margin_q[fixed.name] if fixed.difference == "margin" else (2 * reach) << tf
            q = round_half_away(
                Fraction(gain_mg_per_c[fixed.name]) * per_mdegc * Fraction(2) ** (frac + HI_BITS - tf)
            )
            gains[fixed.name] = QGain(fixed.gain_name, q, diff_bound, diff_bound * abs(q))
        if any(g is not None and abs(g.q) > INT32_MAX for g in gains.values()):
            continue
        bound = (horner[0] << HI_BITS) + sum(g.bound for g in gains.values() if g is not None)
        if bound >= INT64_SAFE:
            continue
        options = {o: any(v[1].option == o for v in present.values()) for o in c_options()}
        # the tag hashes every constant in the registry's layout (a term the model lacks as None)
        layout_margins = tuple(margin_q.get(f.name) for f in layout if f.margin is not None)
        constants = (
            lo,
            hi,
            centre,
            tf,
            *layout_margins,
            *options.values(),
            u_shift,
            d,
            frac,
            filt,
            *gains.values(),
        )
        tag = int(hashlib.sha256(repr(constants).encode()).hexdigest()[:8], 16)
        terms = tuple(
            QTerm(
                identifier,
                None if fixed.tau_s is None else filt[fixed.filter_name],
                gains.get(name),
                margin_q.get(name),
            )
            for name, (identifier, fixed, _) in present.items()
        )
        return QPhysics(
            spec.method,
            limits,
            spec.rate_hz,
            lo,
            hi,
            centre,
            tf,
            terms,
            t_ref,
            u_shift,
            tuple(d),
            tuple(horner),
            frac,
            bound,
            tag,
        )
    raise UserError("physics: coefficients too large for the fixed-point format")


def _c_terms_of(present: Mapping[str, tuple[str, FixedPoint, Mapping[str, float]]]) -> list[FixedPoint]:
    """The registry's C terms (:func:`~trainer.physics.catalogue.streamed.c_terms`) with each present
    one as its model's effect declares it (effects that are the same C share a name)."""
    return [present[f.name][1] if f.name in present else f for f in c_terms()]


def quantise_checkpoint(
    ckpt: Checkpoint, *, accel_limit_g: float = DEFAULT_ACCEL_LIMIT_G, schedule: str = "step"
) -> QuantModel:
    """The fixed-point model of a parsed checkpoint (deterministic: same input, same integers)."""
    limits = _limits(ckpt, accel_limit_g)
    model = ckpt.model
    if schedule not in SCHEDULES:
        raise UserError(f"--schedule must be one of {', '.join(SCHEDULES)}, got {schedule!r}")
    unit = family_of(model)
    if schedule not in unit.schedules:
        raise UserError(f"--schedule {schedule}: only a DLSTM has a network step to spread")
    return unit.quantise(model, limits, schedule)
