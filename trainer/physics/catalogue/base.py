"""The shape of one catalogue definition: what every part of the tool knows about an effect.

A definition is plain data plus plain functions of arrays. The simulator reads its parameters and
its formula; the mismatch finder (``trainer/diagnose``) reads :class:`Finder`; the test bench
(``trainer/diagnose/scenarios.py``) reads :class:`Scenario`. Nothing here imports the finder:
its objects (block data, model terms, the temperature profile) are passed in and only read, and
:class:`FinderData`, :class:`FinderTerm` and :class:`FinderProfile` say what of them the hooks
read, so the type checker sees through every hook.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Protocol

import numpy as np

T_REF_C = 25.0

Bounds = tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class Param:
    """One parameter of an effect or noise term.

    ``rule`` is ``finite``, ``positive`` (> 0) or ``nonnegative`` (>= 0). ``default`` is used when
    the key is absent; a parameter with neither ``default`` nor ``optional`` is required.
    ``plausible`` is the catalogue's plausible range of ``|value|``; the finder flags fitted values
    outside it when ``flagged``.
    """

    name: str
    rule: str = "finite"
    default: float | None = None
    optional: bool = False
    unit: str = ""
    plausible: tuple[float, float] | None = None
    flagged: bool = True


class Signals:
    """What an additive formula may read, sample by sample.

    ``T_b`` is the temperature the bias polynomial reads: ``T_pm``, or what ``poly_temperature``
    makes of it (the play output when ``hysteresis`` is present), computed once when first read.
    ``rate_c_per_min`` is ``dT_die/dt`` (``None``: the formula takes the numerical derivative);
    ``g_in_mg`` the true input (``None`` when unknown). ``play_start_c``: where a play operator
    (the branch effects) starts before the first sample, clamped into ``T_pm[0] +- w/2``; ``None``:
    at ``T_pm[0]``, half-way between the branches (the catalogue's ``P_0 = T_0``).
    """

    def __init__(
        self,
        t: np.ndarray,
        T_die: np.ndarray,
        T_pm: np.ndarray,
        *,
        rate_c_per_min: np.ndarray | None = None,
        g_in_mg: np.ndarray | float | None = None,
        poly_temperature: Callable[[np.ndarray], np.ndarray] | None = None,
        play_start_c: float | None = None,
    ) -> None:
        self.t = t
        self.play_start_c = play_start_c
        self.T_die = T_die
        self.T_pm = T_pm
        self.rate_c_per_min = rate_c_per_min
        self.g_in_mg = g_in_mg
        self._poly_temperature = poly_temperature

    @cached_property
    def T_b(self) -> np.ndarray:  # noqa: N802 (the catalogue's name)
        return self.T_pm if self._poly_temperature is None else self._poly_temperature(self.T_pm)


class FinderData(Protocol):
    """What hooks read of the finder's block means (``trainer.diagnose.blocks.BlockData``)."""

    @property
    def t(self) -> np.ndarray: ...  # block centres (s)
    @property
    def n(self) -> int: ...
    @property
    def block_s(self) -> float: ...
    @property
    def starts(self) -> np.ndarray: ...  # each block's first sample time (s)
    @property
    def duration_s(self) -> float: ...
    @property
    def fine_step_s(self) -> float: ...
    @property
    def full_t(self) -> np.ndarray: ...
    @property
    def known_input_block(self) -> np.ndarray | None: ...
    @property
    def lattice_lsb_c(self) -> float | None: ...
    @property
    def plateaus(self) -> list[tuple[float, float]]: ...
    @property
    def hold_after_ramp_s(self) -> float: ...  # the longest hold after a ramp (s)


class FinderTerm(Protocol):
    """What hooks read of one model term (``trainer.diagnose.model.Term``)."""

    @property
    def identifier(self) -> str: ...
    @property
    def nl(self) -> tuple[float, ...]: ...  # nonlinear values, in Finder.nonlinear order
    @property
    def fixed(self) -> bool: ...
    @property
    def offset(self) -> tuple[float, ...] | None: ...  # held linear values


class FinderSegment(Protocol):
    @property
    def label(self) -> str: ...
    @property
    def start_s(self) -> float: ...
    @property
    def end_s(self) -> float: ...


class FinderProfile(Protocol):
    """What identifiability rules read of the temperature profile (``trainer.diagnose.profile.Profile``)."""

    @property
    def segments(self) -> Sequence[FinderSegment]: ...
    @property
    def reversals(self) -> int: ...
    @property
    def overlap_c(self) -> tuple[float, float] | None: ...
    @property
    def hold_s(self) -> float: ...
    @property
    def holds_after_ramp_s(self) -> float: ...
    @property
    def corners(self) -> int: ...
    @property
    def ramp_rates(self) -> Sequence[float]: ...
    @property
    def duration_s(self) -> float: ...
    @property
    def lattice_lsb_c(self) -> float | None: ...
    @property
    def known_input_varies(self) -> bool: ...
    @property
    def block_t_s(self) -> np.ndarray: ...
    @property
    def block_temp_c(self) -> np.ndarray: ...


@dataclass
class BlockDesign:
    """Work state of one design matrix on block means (``trainer.diagnose.model.build_design``).

    The temperature-chain hooks set ``T_pm`` (proof mass) and ``T_b`` (what the polynomial reads);
    a term with held linear parameters adds its known contribution to ``offset``.
    """

    data: FinderData
    T: np.ndarray  # block temperature (dequantised when a term asks for it)
    rate: np.ndarray  # block dT/dt in degC/min
    T_pm: np.ndarray
    T_b: np.ndarray
    offset: np.ndarray


@dataclass(frozen=True)
class Identifiability:
    identifiable: bool
    reason: str
    test: str = ""  # the test that would make it identifiable (or separate it better)
    weak: bool = False


@dataclass(frozen=True)
class StartingTerm:
    """How an effect of the user's simulation enters the finder's starting model."""

    nl: tuple[float, ...] = ()
    fixed: bool = False
    note: str = ""  # a remark for the report


@dataclass(frozen=True)
class StartContext:
    """What the finder knows when it turns the user's simulation into its starting model."""

    lattice_lsb_c: float | None  # LSB of the thermometer column's lattice, if it lies on one
    input_varies: bool  # the known true input changes (a second orientation)


@dataclass(frozen=True)
class Region:
    """Where something shows: a time range, annotated from the temperature profile."""

    t_start_s: float
    t_end_s: float
    segment: str
    temp_min_c: float
    temp_max_c: float
    branch: str
    significance: Mapping[str, float | str]  # figures, or the selection step's evidence in words
    kind: str = "residual"
    note: str = ""

    def to_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "t_start_s": round(self.t_start_s, 3),
            "t_end_s": round(self.t_end_s, 3),
            "segment": self.segment,
            "temp_min_c": round(self.temp_min_c, 3),
            "temp_max_c": round(self.temp_max_c, 3),
            "branch": self.branch,
            "significance": self.significance,
            "kind": self.kind,
        }
        if self.note:
            out["note"] = self.note
        return out


@dataclass(frozen=True)
class WhereContext:
    """What a ``where`` hook reads: the block data and the finder's helpers, bound to the residual.

    ``window_z(a, b)`` is the starting model's residual summed over blocks ``a:b`` over its standard
    deviation; ``region(a, b, significance, kind, note)`` is the finder's region over blocks ``a:b``.
    """

    data: FinderData
    evidence: str  # the selection step's evidence for the effect
    window_z: Callable[[int, int], float]
    region: Callable[[int, int, Mapping[str, float | str], str, str], Region]


def _no_bounds(data: FinderData) -> Bounds:
    return ()


@dataclass(frozen=True)
class Finder:
    """How the mismatch finder models, searches, reports and judges one catalogue identifier.

    Model terms (effects and the ``rate_ramp`` trend) split into nonlinear parameters, searched
    numerically (``nonlinear``: names and whether the search runs on their log), and linear ones,
    solved by GLS: ``columns`` returns ``(role, column)`` pairs on the block means, and
    ``to_params`` maps a term's nonlinear values and fitted linear values back to catalogue
    parameters. ``search`` names the strategy in ``trainer.diagnose.candidates`` (``profile``: a
    log grid of ``grid_points`` over the single nonlinear parameter within ``bounds(data)``;
    ``linear``: the nonlinear parameter held at its default or, with ``freed_bounds(data)``, also
    profiled freed over that range on a log grid of ``grid_points``, the better by BIC;
    ``lattice``; ``step``; ``sinusoid``; ``noise``), ``None`` when the finder never proposes it. ``noise_role`` for noise terms: ``white`` (always fitted, from the full rate),
    ``covariance`` (a correlated term of the block covariance, ``covariance(n, block_s,
    duration_s)`` for unit coefficient), ``trend`` (a deterministic column) or ``None`` (not
    modelled: the user's value is kept in the augmented simulation). Hooks for special cases:

    - ``event_time``: the first nonlinear parameter is an event time (not learnable after a cut).
    - ``full_rate(lin, data, T_pm)``: the full-rate contribution ``physics.effects.drift`` leaves out.
    - ``where(params, ctx)``: the regions that locate the effect (:class:`WhereContext`), else its visible part.
    - ``absent_when_unidentifiable``: unidentifiable means absent (not listed as not identifiable).
    - ``unused_note(data)``: remark when the recording shows it but the fit does not keep it.
    """

    search: str | None = None
    nonlinear: tuple[tuple[str, bool], ...] = ()
    bounds: Callable[[FinderData], Bounds] = _no_bounds
    grid_points: int = 0
    # ``linear``: also tried freed here, given the block data and the effects already in the model
    freed_bounds: Callable[[FinderData, Collection[str]], Bounds] | None = None
    max_terms: int = 1  # how many instances the finder may add
    # (term, term, block data): two instances coincide within the data's resolution (one instance)
    same_instance: Callable[[FinderTerm, FinderTerm, FinderData], bool] | None = None
    # BIC: parameters the term adds besides its linear columns (None: its free nonlinear ones)
    bic_nonlinear: int | None = None
    columns: Callable[[FinderTerm, BlockDesign], list[tuple[str, np.ndarray]]] | None = None
    proof_mass: Callable[[FinderTerm, np.ndarray, float], np.ndarray] | None = None  # (term, T, block_s)
    dequantize: bool = False  # its presence makes the model read the de-quantised temperature
    fine_offset: Callable[[FinderTerm, np.ndarray], np.ndarray] | None = None  # held part on the fine grid
    to_params: Callable[[FinderTerm, Mapping[str, float]], dict[str, float]] | None = None
    from_config: Callable[[Mapping[str, float], StartContext], StartingTerm] | None = None
    backbone: bool = False  # always in the model, its columns first (only bias_poly)
    identifiability: Callable[[FinderProfile], Identifiability] | None = None
    advice: str = ""
    confounders: tuple[str, ...] = ()
    # what separates it from a confounder: {other identifier: signature}, each pair written once
    separations: Mapping[str, str] = field(default_factory=dict)
    # noise terms
    noise_role: str | None = None
    covariance: Callable[[int, float, float], np.ndarray] | None = None
    start_coefficient: float | None = None  # starting value of the covariance term's coefficient
    allan_variance: Callable[[np.ndarray, float, float, Mapping[str, float]], np.ndarray] | None = None
    # special cases (see the docstring)
    event_time: bool = False
    full_rate: Callable[[Mapping[str, float], FinderData, np.ndarray], np.ndarray | None] | None = None
    where: Callable[[Mapping[str, float], WhereContext], list[Region]] | None = None
    absent_when_unidentifiable: bool = False
    unused_note: Callable[[FinderData], str] | None = None
    config_note: str = ""  # remark when the user's simulation has it but the finder does not model it
    missing_note: str = ""  # remark when the user's simulation lacks it (white noise)


@dataclass(frozen=True)
class Scenario:
    """How the test bench conceals an instance (``trainer.diagnose.scenarios``).

    ``draw(rng, duration_s, sign)`` returns catalogue parameters (``sign`` is +-1, drawn for every
    concealed identifier); ``checked`` are the parameters the finder must recover. The protocol
    flags make the generated test able to show the effect. For noise terms, ``known(rng)`` is the
    level the user's own model carries when the term is not the concealed one.
    """

    draw: Callable[[np.random.Generator, float, float], dict[str, float]] | None = None
    checked: tuple[str, ...] = ()
    needs_reversal: bool = False
    long_holds: bool = False
    min_slope_mg_per_c: float = 0.0  # the bias curve must be this steep for it to matter
    fine_thermometer: bool = False  # a quieter thermometer (its steps would drown otherwise)
    known: Callable[[np.random.Generator], dict[str, float]] | None = None


@dataclass(frozen=True)
class Effect:
    """One bias effect of the catalogue.

    Exactly one of the simulator roles is set: ``contribution(params, signals)`` (additive, mg),
    ``proof_mass(t, T, params)`` (gives ``T_pm``), ``thermometer(temp_c, params)`` (acts on the
    reading only). ``bias_temperature(T_pm, params, play_start_c)`` additionally switches what the
    polynomial reads (``play_start_c``: :attr:`Signals.play_start_c`). ``input_param`` names a parameter that sets the constant true input. ``compensable``:
    a property of the sensor that a temperature-drift compensator models (lag, rate, hysteresis,
    creep, warm-up), as opposed to an event or a property of the test set-up (a step, a chamber
    oscillation, the thermometer's resolution). ``excludes``: identifiers that describe the same
    physics another way; a configuration or a model never holds both.
    """

    identifier: str
    params: tuple[Param, ...]
    summary: str
    contribution: Callable[[Mapping[str, float], Signals], np.ndarray] | None = None
    proof_mass: Callable[[np.ndarray, np.ndarray, Mapping[str, float]], np.ndarray] | None = None
    thermometer: Callable[[np.ndarray, Mapping[str, float]], np.ndarray] | None = None
    bias_temperature: Callable[[np.ndarray, Mapping[str, float], float | None], np.ndarray] | None = None
    multi_instance: bool = False
    input_param: str | None = None
    compensable: bool = False
    excludes: tuple[str, ...] = ()  # identifiers it must not be combined with (the same physics twice)
    sampling_check: Callable[[Mapping[str, float], float], str | None] | None = None
    finder: Finder = Finder()
    scenario: Scenario | None = None

    @property
    def temperature_chain(self) -> bool:
        return self.contribution is None


@dataclass(frozen=True)
class NoiseTerm:
    """One IEEE Std 952 noise term: ``synthesize(params, n, dt_s, rng)`` gives ``n`` samples (mg)."""

    identifier: str
    params: tuple[Param, ...]
    summary: str
    synthesize: Callable[[Mapping[str, float], int, float, np.random.Generator], np.ndarray]
    finder: Finder = Finder()
    scenario: Scenario | None = None


def sample_period(t: np.ndarray) -> float:
    """Mean sample period; the low-pass assumes uniform sampling (recordings allow 1 % jitter)."""
    if t.size < 2:
        raise ValueError("need at least two samples")
    return float(t[-1] - t[0]) / (t.size - 1)


def rate_c_per_min(t: np.ndarray, T_die: np.ndarray) -> np.ndarray:
    """Numerical ``dT_die/dt`` in degC/min (central differences) for callers without the LP state."""
    return np.gradient(np.asarray(T_die, dtype=np.float64), np.asarray(t, dtype=np.float64)) * 60.0


def catalogue_params(
    definition: Effect | NoiseTerm, term: FinderTerm, linear: Mapping[str, float]
) -> dict[str, float]:
    """A fitted model term as catalogue parameters (catalogue order).

    The definition's ``to_params`` when it has one; otherwise each parameter is the term's linear
    coefficient of that name or its nonlinear value of that name (optional ones absent from both
    are left out), which is what almost every effect needs.
    """
    if definition.finder.to_params is not None:
        return definition.finder.to_params(term, linear)
    nonlinear = [name for name, _ in definition.finder.nonlinear]
    params: dict[str, float] = {}
    for param in definition.params:
        if param.name in linear:
            params[param.name] = linear[param.name]
        elif param.name in nonlinear:
            params[param.name] = term.nl[nonlinear.index(param.name)]
    return params


def starting_term(
    definition: Effect | NoiseTerm, params: Mapping[str, float], context: StartContext
) -> StartingTerm:
    """How a configured instance enters the finder's starting model: the definition's
    ``from_config`` when it has one, else its nonlinear parameters as configured, searched."""
    if definition.finder.from_config is not None:
        return definition.finder.from_config(params, context)
    return StartingTerm(tuple(params[name] for name, _ in definition.finder.nonlinear))
