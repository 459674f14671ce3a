"""The shape of a streamed effect: what the physics compensator and its C export need of an effect.

A catalogue effect the compensator carries has a sibling module ``<effect>_stream.py`` holding one
:class:`StreamedEffect`: its recurrence in float64 (one step per thermometer sample), and, when the
C export carries it, its fixed-point form (:class:`FixedPoint`): what it quantises (a low-pass,
a gain, an int32 temperature margin), its step on Python integers (the golden model) and its C
step snippets. Generic code (``trainer/greybox/stream.py``, ``codegen/``) loops over the registry
(:mod:`trainer.physics.catalogue.streamed`) and never names an effect.

Order of one step (every effect's part in its phase, phases in this order, registry order within):

    CHAIN     before the polynomial, gives the proof-mass temperature T_pm from T
    BRANCH    before the polynomial, reads T_pm (may switch what the polynomial reads, T_b)
    ADDITIVE  after the polynomial, adds a term

Pure data and plain functions: nothing here imports codegen (codegen reads these through the registry).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import Literal, Protocol

from trainer.physics.thermal import lowpass_coefficients

CHAIN, BRANCH, ADDITIVE = 0, 1, 2
HI_BITS = 32  # an int64 filter state's high word is its int32 temperature (tdcp_hi)

Params = Mapping[str, float]


# ---------------------------------------------------------------------------------- float64 stream
@dataclass
class Sample:
    """One float step's signals: the clipped temperature ``T`` and the previous one (degC), the
    proof-mass temperature ``T_pm`` and what the polynomial reads ``T_b`` (a CHAIN or BRANCH part
    may set them), and the time since power-on (s)."""

    T: float
    T_prev: float
    T_pm: float
    T_b: float
    time_s: float


Lowpass = tuple[float, float, float]  # (a, b0, b1) of y' = a y + b0 x + b1 x_prev


def lowpass_constants(tau_s: float, dt_s: float) -> Lowpass:
    """The simulator's exact first-order-hold low-pass (:func:`trainer.physics.thermal.lowpass`)."""
    (b0, b1), (_, minus_a) = lowpass_coefficients(tau_s, dt_s)
    return (-float(minus_a), float(b0), float(b1))


def lowpass_step(f: tuple[float, ...], y: float, s: Sample) -> float:
    a, b0, b1 = f
    return a * y + b0 * s.T + b1 * s.T_prev


# ---------------------------------------------------------------------------------- fixed point
@dataclass
class IntSample:
    """One integer step's signals (golden model): ``x`` and ``prev`` the temperature and the previous
    one in Q(tf) mdegC about the centre, ``step_mdegc`` their difference in mdegC, ``t_pm`` and
    ``t_b`` as in :class:`Sample` (Q(tf))."""

    x: int
    prev: int
    step_mdegc: int
    temp_frac: int
    t_pm: int
    t_b: int


class IntLowpass(Protocol):
    @property
    def c_q(self) -> int: ...
    @property
    def b_q(self) -> int: ...
    @property
    def shift(self) -> int: ...


class IntGain(Protocol):
    @property
    def q(self) -> int: ...


class IntTerm(Protocol):
    """What the quantiser made of one effect (``codegen.families.physics.quantise.QTerm``)."""

    @property
    def filter(self) -> IntLowpass | None: ...
    @property
    def gain(self) -> IntGain | None: ...
    @property
    def margin_q(self) -> int | None: ...


GoldenStep = Callable[[dict[str, int], IntSample], int]
"""One term's golden-model step with its constants: advances its state words in ``values`` and
returns its drift term (see :class:`FixedPoint`)."""


def lowpass_int(f: IntLowpass) -> Callable[[int, IntSample], int]:
    """``tdcp_lowpass`` with the filter ``f``'s constants, on Python integers (floors as the exact
    ``>>``): ``lowpass_int(f)(y, s)`` is the state after ``y``."""
    c, b0, shift = f.c_q, f.b_q, f.shift

    def lowpass(y: int, s: IntSample) -> int:
        d = ((s.prev << HI_BITS) - y) >> (HI_BITS + shift)
        return y + d * c + (s.step_mdegc << (s.temp_frac - shift)) * b0

    return lowpass


def lowpass_call(word: str) -> str:
    """The C kernel call that steps the int64 state ``word`` (a C snippet line, see :class:`FixedPoint`)."""
    return (
        f"    state->{word} = tdcp_lowpass(state->{word}, prev, step * ${{step_scale}}, ${{c}}, ${{b0}}, "
        "${shift});\n"
    )


@dataclass(frozen=True)
class StateWord:
    """One word of the C state (and the golden model's and the float stream's state of that name).

    ``wide``: int64 Q(tf + 32) mdegC, a filter state whose high word is the temperature; else an
    int32 Q(tf) temperature. ``doc`` describes it in the one-channel module's state struct,
    ``imu_doc`` an int32 word in the IMU module's (None: no comment; the int64 words share one)."""

    name: str
    wide: bool
    doc: str
    imu_doc: str | None = None


@dataclass(frozen=True)
class FixedPoint:
    """The C export's form of a streamed effect.

    ``name`` is its C term: the bit ``NAME_PHYS_<NAME>`` of an IMU physics channel, its IMU table
    fields ``<name>`` (its filter, a ``tdcp_lowpass``) and ``<name>_q`` (its gain). Effects that are the
    same C (hysteresis and hysteresis_offset) share a name and declare the same layout.

    What it quantises (each a function of the effect's catalogue parameters): ``tau_s`` its low-pass
    of T (the state's wide word, named ``filter_name`` in the model tag and the manifest);
    ``gain_mg_per_c`` the gain on its difference (``difference``: ``temperature``, the temperature
    minus its filter, within the range; or ``margin``, bounded by its margin), named ``gain_name``;
    ``margin`` an int32 temperature offset ``(mdegC, what it is)`` (the play operator's half width)
    that every int32 temperature must leave room for, the IMU table field ``margin_field``;
    ``proof_mass_weight``: how much its gain adds to the drift's sensitivity to T_pm (the proof-mass
    filter's error budget). ``poly_reads``: the state word the polynomial reads when present (an
    IMU option bit ``READS_<WORD>``).

    ``golden(term)``: the step on Python integers with the term's constants, ``step(values, sample)``
    (a :data:`GoldenStep`: advances its state words, returns its int64 drift term in Q(frac + 32),
    and may set ``sample.t_pm`` / ``t_b``). ``before_poly`` / ``after_poly``: its C step
    (``string.Template`` text, lines indented by four) before and after the polynomial, with
    ``${c} ${b0} ${shift} ${step_scale}`` (its filter), ``${q}`` (its gain), ``${margin}`` and
    ``${margin_text}`` (its margin, and that value with its format) filled in by the renderer.
    """

    name: str
    state: tuple[StateWord, ...]
    golden: Callable[[IntTerm], GoldenStep]
    before_poly: str = ""
    after_poly: str = ""
    tau_s: Callable[[Params], float] | None = None
    filter_name: str = ""
    filter_doc: str = ""
    gain_mg_per_c: Callable[[Params], float] | None = None
    gain_name: str = ""
    difference: Literal["temperature", "margin"] = "temperature"
    difference_text: str = ""
    margin: Callable[[Params], tuple[Fraction, str]] | None = None
    margin_field: str = ""
    margin_doc: str = ""
    proof_mass_weight: float = 0.0
    poly_reads: str | None = None

    @property
    def option(self) -> str | None:
        return None if self.poly_reads is None else f"READS_{self.poly_reads.upper()}"


@dataclass(frozen=True)
class StreamedEffect:
    """One catalogue effect as the physics compensator streams it.

    ``prepare(params, dt_s)`` gives the constants of one sample period; ``step(params, constants,
    values, sample)`` advances the effect's state words in ``values`` (each starts at the first
    clipped temperature) and returns its drift (mg; a CHAIN or BRANCH part may set ``sample.T_pm``
    / ``T_b``). ``check(params)`` raises ValueError when the streaming form cannot carry the
    parameters. ``needs_power_on_time``: it reads the time since power-on (only with ``--warmup``).
    ``fixed``: its C form; None when the export does not carry it, and then ``unexported(params)``
    says why (None: it contributes nothing, the export leaves it out). ``min_filter_s``: the
    compensator's fit holds its (single, time-constant) nonlinear parameter at least this."""

    identifier: str
    phase: int
    state: tuple[str, ...]
    prepare: Callable[[Params, float], tuple[float, ...]]
    step: Callable[[Params, tuple[float, ...], dict[str, float], Sample], float]
    check: Callable[[Params], None] | None = None
    needs_power_on_time: bool = False
    fixed: FixedPoint | None = None
    unexported: Callable[[Params], str | None] | None = None
    min_filter_s: float | None = None

    def __post_init__(self) -> None:
        if self.fixed is not None:
            assert self.state == tuple(w.name for w in self.fixed.state), self.identifier


def filtered_difference(
    word: str,
    *,
    name: str,
    identifier: str,
    doc: str,
    tau_s: Callable[[Params], float],
    gain_mg_per_c: Callable[[Params], float],
    letter: str,
) -> FixedPoint:
    """The C form of ``gain (T - LP(T, tau_s))`` with the low-pass in the state word ``word``
    (``doc``: what it is, e.g. ``the rate filter``, ``letter`` its symbol; the term's filter and
    gain take ``identifier``'s name)."""

    def golden(q: IntTerm) -> GoldenStep:
        assert q.filter is not None and q.gain is not None
        lowpass, gain = lowpass_int(q.filter), q.gain.q

        def step(v: dict[str, int], s: IntSample) -> int:
            v[word] = y = lowpass(v[word], s)
            return (s.x - (y >> HI_BITS)) * gain

        return step

    return FixedPoint(
        name=name,
        state=(StateWord(word, True, f"{identifier}: {doc} {letter}"),),
        golden=golden,
        after_poly=lowpass_call(word) + f"    acc += (int64_t)(x - tdcp_hi(state->{word})) * ${{q}};\n",
        tau_s=tau_s,
        filter_name=identifier,
        filter_doc=f"{identifier}: {doc}",
        gain_mg_per_c=gain_mg_per_c,
        gain_name=identifier,
        difference_text=f"(T - {letter})",
    )
