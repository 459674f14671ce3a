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
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from fractions import Fraction

import numpy as np

from codegen.families.physics.spec import PhysicsSpec
from codegen.fixedpoint import INT32_MAX, INT64_MAX, round_half_away
from codegen.quantize import ACCEL_PER_MG, INT64_SAFE, Limits
from trainer.errors import UserError
from trainer.physics.catalogue.streamed import STREAMED, c_options, c_terms, instance_suffixes, play_words
from trainer.physics.catalogue.streaming import CHAIN, HI_BITS, FixedPoint, StateWord

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
    # its state words' suffix: "" for an effect's first instance, "_2", "_3", ... for later ones
    # (trainer.physics.catalogue.streamed.instance_suffixes)
    suffix: str = ""

    @property
    def fixed(self) -> FixedPoint:
        fixed = STREAMED[self.identifier].fixed
        assert fixed is not None
        return fixed

    @property
    def words(self) -> tuple[StateWord, ...]:
        """Its state words as the C state, the golden model and the float stream name them."""
        return instance_words(self.fixed, self.suffix)

    @property
    def poly_reads(self) -> str | None:
        """The state word the polynomial reads after this term's step (None: it does not switch it)."""
        reads = self.fixed.poly_reads
        return None if reads is None else reads + self.suffix

    @property
    def gain_name(self) -> str:
        return self.fixed.gain_name + self.suffix

    @property
    def difference_text(self) -> str:
        return instance_text(self.fixed, self.fixed.difference_text, self.suffix)


def instance_words(fixed: FixedPoint, suffix: str) -> tuple[StateWord, ...]:
    """``fixed``'s state words of the instance with ``suffix`` (its own words, its own symbols)."""
    if not suffix:
        return fixed.state
    return tuple(
        replace(
            w,
            name=w.name + suffix,
            doc=instance_text(fixed, w.doc, suffix),
            imu_doc=None if w.imu_doc is None else f"{w.imu_doc}, instance {suffix[1:]}",
        )
        for w in fixed.state
    )


def _symbol(fixed: FixedPoint) -> str | None:
    """The symbol of a term's state in its formula (``P`` of ``(T_pm - P)``), None when it has none."""
    found = re.fullmatch(r"\(\s*\w+\s*-\s*(\w+)\s*\)", fixed.difference_text)
    return None if found is None else found.group(1)


def instance_text(fixed: FixedPoint, text: str, suffix: str) -> str:
    """``text`` (a formula or a state word's description) of the instance with ``suffix``: its
    symbol suffixed too (``P_2``)."""
    symbol = _symbol(fixed)
    if not suffix or symbol is None:
        return text
    return re.sub(rf"\b{re.escape(symbol)}\b", symbol + suffix, text)


def rename_words(fixed: FixedPoint, code: str, suffix: str) -> str:
    """A term's C step ``code`` on the state words of its instance with ``suffix`` (the catalogue's
    snippets name the first instance's: ``state->play`` becomes ``state->play_2``)."""
    for word in fixed.state if suffix else ():
        code = re.sub(rf"\bstate->{re.escape(word.name)}\b", f"state->{word.name}{suffix}", code)
    return code


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
        width, in Q(tf). The IMU module's ``NAME_restore`` computes the same numbers in C from the
        calibration it restores under (``_physics_imu.j2``, ``physics_saved_ok``: clip range, centre,
        ``scale`` = 2^tf, half widths); tests/export/test_imu_restore.py checks they agree."""
        margin = max((t.margin_q for t in self.terms if t.margin_q is not None), default=0)
        wide = self.reach_mdegc << (self.temp_frac + HI_BITS)
        narrow = (self.reach_mdegc << self.temp_frac) + margin
        return {w.name: wide if w.wide else narrow for w in self.words}

    @property
    def words(self) -> tuple[StateWord, ...]:
        """Every state word of its terms (each instance its own), in step order."""
        return tuple(w for t in self.terms for w in t.words)

    @property
    def play_words(self) -> frozenset[str]:
        """Its state words that are a play operator's output (every instance's): where the play starts."""
        play = play_words()
        return frozenset(w.name + t.suffix for t in self.terms for w in t.fixed.state if w.name in play)

    @property
    def filters(self) -> tuple[QLowpass, ...]:
        return tuple(t.filter for t in self.terms if t.filter is not None)

    @property
    def gains(self) -> tuple[QGain, ...]:
        return tuple(t.gain for t in self.terms if t.gain is not None)

    @property
    def options(self) -> tuple[str, ...]:
        """The option bits its terms set (what the polynomial reads), each once."""
        return tuple(dict.fromkeys(t.fixed.option for t in self.terms if t.fixed.option is not None))

    @property
    def poly_reads(self) -> str | None:
        """The state word the polynomial reads instead of T_pm (None: T_pm): the last term's in step
        order that switches it, as the float stream's and the golden model's steps leave T_b."""
        return next((t.poly_reads for t in reversed(self.terms) if t.poly_reads is not None), None)


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


def _check_filters_budget(filters: list[QLowpass], rate_hz: float, unit: str = "mg") -> None:
    """The filters' state error bounds, in drift, add up to at most :data:`PHYS_FILTERS_BUDGET_MG`
    (one pool, in the channel's ``unit``: the budget of docs/codegen.md is in it)."""
    from codegen.step_units import STEP_UNITS

    label = STEP_UNITS[unit].label
    total_mg = sum(q.error_mg for q in filters)
    if total_mg > PHYS_FILTERS_BUDGET_MG:
        worst = max(filters, key=lambda q: q.error_mg)
        raise UserError(
            f"physics: the filters would stray {total_mg:.3g} {label} of drift from the float model at "
            f"{rate_hz:g} Hz (budget {PHYS_FILTERS_BUDGET_MG:g} {label}), most of it the {worst.name} filter "
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
    # the terms the C carries, in step order, keyed by C term and instance (``branch``, ``branch_2``):
    # each instance of an effect its own constants and state words
    suffixes = instance_suffixes([term.identifier for term in m.terms])
    carried = [
        _Present(term.identifier, fixed, term.params, suffix)
        for term, suffix in zip(m.terms, suffixes, strict=True)
        if (fixed := STREAMED[term.identifier].fixed) is not None
    ]
    _check_words(carried)
    present = {v.fixed.name + v.suffix: v for v in carried}
    first = {v.fixed.name: v for v in present.values() if not v.suffix}  # the registry's layout's
    later = [(key, v) for key, v in present.items() if v.suffix]  # an effect's further instances
    margins: dict[str, tuple[Fraction, str]] = {}
    for key, v in present.items():
        if v.fixed.margin is not None:
            margins[key] = v.fixed.margin(v.params)
            if not margins[key][0] > 0:
                raise UserError(f"physics: {margins[key][1]} must be positive")
    tf = -1
    for k in range(MAX_TEMP_FRAC, -1, -1):
        h_q = max((round_half_away(half * 2**k) for half, _ in margins.values()), default=0)
        if (2 * reach) << k <= INT32_MAX and (reach << k) + h_q <= INT32_MAX:
            tf = k
            break
    if tf < 0:
        widest = max(margins.values(), key=lambda v: v[0])[1] if margins else "a margin"
        raise UserError(f"physics: {widest} is too wide for int32 temperatures")
    margin_q = {key: round_half_away(half * 2**tf) for key, (half, _) in margins.items()}
    # the play start, a temperature within the range (PhysicsModel clips it) like every other x
    play_start_q = None
    if m.play_start_c is not None and any(
        w.name in play_words() for v in present.values() for w in v.fixed.state
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
        key: v.fixed.gain_mg_per_c(v.params)
        for key, v in present.items()
        if v.fixed.gain_mg_per_c is not None
    }
    proof_mass = slope + sum(  # every instance's gain on T_pm
        v.fixed.proof_mass_weight * abs(gain_mg_per_c[key])
        for key, v in present.items()
        if v.fixed.proof_mass_weight
    )

    def lowpass_of(key: str) -> QLowpass:
        v = present[key]
        assert v.fixed.tau_s is not None
        chain = STREAMED[v.identifier].phase == CHAIN
        sensitivity = proof_mass if chain else abs(gain_mg_per_c[key])
        name = v.fixed.filter_name + v.suffix
        return _lowpass(name, v.fixed.tau_s(v.params), spec.rate_hz, tf, reach, span, sensitivity)

    layout = _c_terms_of(first)
    filt: dict[str, QLowpass | None] = {}  # the layout's (first instances'), by filter name
    for fixed in layout:
        if fixed.tau_s is not None:
            filt[fixed.filter_name] = lowpass_of(fixed.name) if fixed.name in first else None
    later_filt = {key: lowpass_of(key) for key, v in later if v.fixed.tau_s is not None}
    _check_filters_budget(
        [q for q in filt.values() if q is not None] + list(later_filt.values()), spec.rate_hz, limits.unit
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

    def gain_of(key: str, frac: int) -> QGain:
        v = present[key]
        diff_bound = margin_q[key] if v.fixed.difference == "margin" else (2 * reach) << tf
        q = round_half_away(Fraction(gain_mg_per_c[key]) * per_mdegc * Fraction(2) ** (frac + HI_BITS - tf))
        return QGain(v.fixed.gain_name + v.suffix, q, diff_bound, diff_bound * abs(q))

    for frac in range(MAX_DRIFT_FRAC, -1, -1):
        d = [round_half_away(v * Fraction(2) ** (frac + k)) for k, v in enumerate(a)]
        horner = _horner_bounds(d)
        if max(horner) > INT32_MAX:
            continue
        gains: dict[str, QGain | None] = {  # the layout's (first instances'), by C term
            fixed.name: gain_of(fixed.name, frac) if fixed.name in first else None for fixed in gain_terms
        }
        later_gains = {key: gain_of(key, frac) for key, v in later if v.fixed.gain_mg_per_c is not None}
        every_gain = [g for g in gains.values() if g is not None] + list(later_gains.values())
        if any(abs(g.q) > INT32_MAX for g in every_gain):
            continue
        bound = (horner[0] << HI_BITS) + sum(g.bound for g in every_gain)  # every instance's term
        if bound >= INT64_SAFE:
            continue
        options = {o: any(v.fixed.option == o for v in present.values()) for o in c_options()}
        # the tag hashes every constant in the registry's layout (a term the model lacks as None), then
        # an effect's further instances' (a model without any keeps its tag)
        layout_margins = tuple(margin_q.get(f.name) for f in layout if f.margin is not None)
        instances = tuple(
            (key, margin_q.get(key), later_filt.get(key), later_gains.get(key)) for key, _ in later
        )
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
            *((("instances", instances),) if instances else ()),
        )
        tag = int(hashlib.sha256(repr(constants).encode()).hexdigest()[:8], 16)
        terms = tuple(
            QTerm(
                v.identifier,
                None
                if v.fixed.tau_s is None
                else (later_filt[key] if v.suffix else filt[v.fixed.filter_name]),
                later_gains.get(key) if v.suffix else gains.get(v.fixed.name),
                margin_q.get(key),
                v.suffix,
            )
            for key, v in present.items()
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


@dataclass(frozen=True)
class _Present:
    """One term of the model the C carries: its effect, C form, parameters and instance suffix."""

    identifier: str
    fixed: FixedPoint
    params: Mapping[str, float]
    suffix: str


def _check_words(present: list[_Present]) -> None:
    """Each term keeps its own state words: two effects that are the same C term (their first
    instances would share its words, e.g. the play operator's) cannot both be carried."""
    owner: dict[str, str] = {}
    for v in present:
        for w in v.fixed.state:
            word = w.name + v.suffix
            if word in owner:
                raise UserError(
                    f"physics: {owner[word]} and {v.identifier} would share the C state word {word!r}; "
                    "the export carries one of them (they describe the same physics twice)"
                )
            owner[word] = v.identifier


def _c_terms_of(first: Mapping[str, _Present]) -> list[FixedPoint]:
    """The registry's C terms (:func:`~trainer.physics.catalogue.streamed.c_terms`) with each present
    one as its model's effect declares it (effects that are the same C share a name)."""
    return [first[f.name].fixed if f.name in first else f for f in c_terms()]
