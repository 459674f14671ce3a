"""The physics family's quantiser: int32 temperatures, int64 filter states, int32 x int32 products.

=====================  ===========  ======================================================
quantity               storage      format
=====================  ===========  ======================================================
temperatures           int32        Q(tf) mdegC about the range's centre (play operator), see
                                    :func:`quantise_physics`
filter states          int64        Q(tf + 32) mdegC: the high word is the int32 temperature
coefficients           int32        filters Q(32 + s); cubic d_k Q(f + k); drift accumulator int64 Q(f + 32)
=====================  ===========  ======================================================
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from codegen.families.physics.spec import PhysicsSpec
from codegen.fixedpoint import INT32_MAX, INT64_MAX, round_half_away
from codegen.quantize import ACCEL_PER_MG, INT64_SAFE, Limits
from trainer.errors import UserError
from trainer.physics.catalogue.streamed import STREAMED, c_options, c_terms, play_words
from trainer.physics.catalogue.streaming import CHAIN, HI_BITS, FixedPoint

MAX_TEMP_FRAC = 24  # finer int32 temperatures buy nothing (the filters' floors are bounded below)
MAX_DRIFT_FRAC = 30
# the filters' states together (bound of drift): under the 1e-3 mg budget with the polynomial's rounding.
# One pool, not a share per filter: a slow lag on a steep loop may spend what a quiet rate filter leaves.
PHYS_FILTERS_BUDGET_MG = 9e-4


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
    """The grey-box model in int32 temperatures and products (see :func:`quantise_physics`)."""

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
    # where the play operator starts at power-on (x of the model's play start), None: at the first x
    play_start_q: int | None = None

    @property
    def reach_mdegc(self) -> int:
        """|temperature or filter state - centre| at most, mdegC: the range and the floors' margin."""
        return state_reach_mdegc(self.clip_lo_mdegc, self.clip_hi_mdegc, self.centre_mdegc)

    @property
    def word_bounds(self) -> dict[str, int]:
        """|state word| at most after any step, per word of the state: what the step's overflow proofs
        assume of a state, and what ``NAME_restore`` checks of a saved one. A filter state (wide) stays
        within the range in Q(tf + 32); a play operator output within the range widened by its half
        width, in Q(tf)."""
        margin = max((t.margin_q for t in self.terms if t.margin_q is not None), default=0)
        wide = self.reach_mdegc << (self.temp_frac + HI_BITS)
        narrow = (self.reach_mdegc << self.temp_frac) + margin
        return {w.name: wide if w.wide else narrow for t in self.terms for w in t.fixed.state}

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


def state_reach_mdegc(lo_mdegc: int, hi_mdegc: int, centre_mdegc: int) -> int:
    """|state - centre| at most, mdegC: the range's far end plus 2 mdegC for the filters' floors."""
    return max(hi_mdegc - centre_mdegc, centre_mdegc - lo_mdegc) + 2


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
    if error > 1:
        raise UserError(
            f"physics: {name} filter (tau {tau_s:g} s at {rate_hz:g} Hz) would stray {float(error):.3g} mdegC "
            "from the float model (more than 1 mdegC)"
        )
    return QLowpass(name, tau_s, c_q, b_q, shift, float(c), float(b0), float(error), sensitivity)


def _check_filters_budget(filters: list[QLowpass], rate_hz: float) -> None:
    """The filters' state errors, in drift, add up to at most :data:`PHYS_FILTERS_BUDGET_MG`."""
    total_mg = sum(q.error_mg for q in filters)
    if total_mg > PHYS_FILTERS_BUDGET_MG:
        worst = max(filters, key=lambda q: q.error_mg)
        raise UserError(
            f"physics: the filters would stray {total_mg:.3g} mg of drift from the float model at "
            f"{rate_hz:g} Hz (budget {PHYS_FILTERS_BUDGET_MG:g} mg), most of it the {worst.name} filter "
            f"(tau {worst.tau_s:g} s: {worst.error_mdegc:.3g} mdegC)"
        )


def _horner_bounds(d: list[int]) -> list[int]:
    """|p_k| of ``p_3 = d_3, p_k = d_k + floor(p_(k+1) u / 2^32 + 1/2)`` for any |u| < 2^31."""
    bounds = [abs(d[3])]
    for k in (2, 1, 0):
        bounds.insert(0, abs(d[k]) + (bounds[0] + 1) // 2)
    return bounds


def quantise_physics(spec: PhysicsSpec, limits: Limits, schedule: str = "step") -> QPhysics:
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
    reach = state_reach_mdegc(lo, hi, centre)
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
    # the play start, a temperature within the range (PhysicsModel clips it) like every other x
    play_start_q = None
    if m.play_start_c is not None and any(
        w.name in play_words() for _, f, _ in present.values() for w in f.state
    ):
        start = min(max(round_half_away(Fraction(m.play_start_c) * 1000), lo), hi)
        play_start_q = (start - centre) << tf
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
    _check_filters_budget([q for q in filt.values() if q is not None], spec.rate_hz)
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
            *(
                () if play_start_q is None else (("play_start", play_start_q),)
            ),  # older models keep their tags
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
            play_start_q,
        )
    raise UserError("physics: coefficients too large for the fixed-point format")


def _c_terms_of(present: Mapping[str, tuple[str, FixedPoint, Mapping[str, float]]]) -> list[FixedPoint]:
    """The registry's C terms (:func:`~trainer.physics.catalogue.streamed.c_terms`) with each present
    one as its model's effect declares it (effects that are the same C share a name)."""
    return [present[f.name][1] if f.name in present else f for f in c_terms()]
