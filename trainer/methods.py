"""THE list of compensation methods: one :class:`Method` entry per method, in comparison order.

Everything that needs to know the methods derives from :data:`REGISTRY`: ``trainer fit --method``
and ``trainer compare --methods`` (choices, options), the comparison (order, the paper's subset,
range checks, the shared DLSTM population), checkpoints (name <-> class) and the code generator
(which renderer, if any). Adding a method is one new module plus one :func:`register` call here.

Each entry names its class by import path (``"package.module:Class"``) and the class is imported
on first use, so that importing this module (and ``trainer --help``) does not import torch.
``tests/methods/test_method_registry.py`` resolves every entry.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

from trainer.errors import UserError
from trainer.options.methods import (
    DLSTM_OPTIONS,
    NO_OPTIONS,
    PHYSICS_OPTIONS,
    PLA_OPTIONS,
    POLY3_OPTIONS,
    OptionGroup,
)

if TYPE_CHECKING:
    from trainer.compensator import Compensator

Family = Literal["memoryless", "temperature-driven", "recursive"]
MEMORYLESS: Family = "memoryless"  # a function of the present temperature
TEMPERATURE_DRIVEN: Family = "temperature-driven"  # a stateful function of the temperature history
RECURSIVE: Family = "recursive"  # uses the past output
FAMILIES: tuple[Family, ...] = (MEMORYLESS, TEMPERATURE_DRIVEN, RECURSIVE)

# The code generator's built-in renderers, in export order: each names a C family of codegen/family.py
# (which checks the names; a test may register more).
Renderer = str
RENDERERS: tuple[Renderer, ...] = ("lstm-stream", "mean-stream", "pla", "cubic", "physics")
PHYSICS_RENDERER: Renderer = "physics"  # the grey-box compensator's C (codegen/families/physics)

# The names other modules refer to in code (each written once, here, and registered below).
PLA = "pla"
CUBIC = "poly3"  # the flight stacks' cubic in temperature
PHYSICS = "physics"
DLSTM = "dlstm"  # the paper's recursive network
DLSTM_TEMP = "dlstm-temp"  # the temperature-input network


@dataclass(frozen=True)
class PaperRow:
    """Guo et al. 2023, Table 1 row of a paper method: (value, improvement %) per Allan term."""

    B: tuple[float, float]  # mg
    K: tuple[float, float]  # mg/s^1/2
    R: tuple[float, float]  # mg/s
    Aver: float  # mean improvement, %

    def term(self, name: str) -> tuple[float, float]:
        """(value, improvement %) of the Allan term ``name`` (B, K or R)."""
        value: tuple[float, float] = getattr(self, name)
        return value


@dataclass(frozen=True, eq=False)
class Method:
    """One compensation method and everything the tool needs to know about it.

    ``implementation`` is the class or its import path ``"package.module:Class"``.
    ``shares_population``: ``trainer compare`` gradient-trains one DLSTM population and every
    method with this flag refines that same population (``fit_from_population``).
    ``reference``: a trivial predictor kept for honest scoring; not offered by ``trainer fit`` and
    not drawn in the fit figures. ``renderer``: codegen's renderer, None = no code generator.
    ``paper_table1``: the method's row of the paper's Table 1; set exactly for the paper's methods.
    ``min_temp_span_c``: the temperature span a training recording needs to determine the method's
    shape in temperature (``trainer fit`` refuses less); 0 = no requirement.
    """

    name: str
    implementation: str | type[Compensator] = field(repr=False)
    family: Family
    options: OptionGroup = field(default=NO_OPTIONS, repr=False)
    renderer: Renderer | None = None
    shares_population: bool = False
    reference: bool = False
    paper_table1: PaperRow | None = field(default=None, repr=False)
    min_temp_span_c: float = 0.0

    def __post_init__(self) -> None:
        if self.family not in FAMILIES:
            raise ValueError(f"method {self.name!r}: family {self.family!r} is not one of {FAMILIES}")

    @property
    def cls(self) -> type[Compensator]:
        """The implementing class (imported on first use)."""
        if not isinstance(self.implementation, str):
            return self.implementation
        module, _, name = self.implementation.partition(":")
        found: type[Compensator] = getattr(importlib.import_module(module), name)
        return found

    @property
    def paper(self) -> bool:
        """One of the four methods of Guo et al. 2023."""
        return self.paper_table1 is not None

    @property
    def range_checked(self) -> bool:
        """A function of the temperature: scored separately outside the training temperature range."""
        return self.family in (MEMORYLESS, TEMPERATURE_DRIVEN)

    @property
    def in_fit_cli(self) -> bool:
        return not self.reference


REGISTRY: dict[str, Method] = {}


def register(method: Method) -> Method:
    """Add ``method`` at the end of the registry (the comparison order); a name is registered once."""
    if method.name in REGISTRY:
        raise ValueError(f"method {method.name!r} is already registered")
    if not method.name or method.name != method.name.strip() or "," in method.name:
        raise ValueError(f"method name {method.name!r} must be non-empty, without spaces or commas")
    REGISTRY[method.name] = method
    return method


def unregister(name: str) -> None:
    """Remove a method (for tests that register a throwaway one)."""
    del REGISTRY[name]


def get(name: str) -> Method:
    """The entry of ``name``; a :class:`UserError` naming the choices when there is none."""
    if name not in REGISTRY:
        raise UserError(f"--method: unknown method {name!r}; choose one of {', '.join(sorted(REGISTRY))}")
    return REGISTRY[name]


def names() -> tuple[str, ...]:
    """Every method, in comparison order."""
    return tuple(REGISTRY)


def entries() -> Iterator[Method]:
    return iter(tuple(REGISTRY.values()))


def fit_cli_names() -> tuple[str, ...]:
    """The choices of ``trainer fit --method``."""
    return tuple(m.name for m in entries() if m.in_fit_cli)


def paper_names() -> tuple[str, ...]:
    return tuple(m.name for m in entries() if m.paper)


def with_renderer() -> tuple[str, ...]:
    """The methods ``codegen export`` supports."""
    return tuple(m.name for m in entries() if m.renderer is not None)


def name_of(model: Compensator | type[Compensator]) -> str:
    """The registered name of ``model``'s exact class (a subclass never inherits its parent's name)."""
    cls = model if isinstance(model, type) else type(model)
    for method in entries():
        if method.cls is cls:
            return method.name
    raise ValueError(f"{cls.__module__}.{cls.__qualname__} is not a registered method")


# -- the methods, in comparison order -------------------------------------------------------------
register(
    Method(
        DLSTM,
        "trainer.dlstm.compensators:RecursiveDLSTM",
        RECURSIVE,
        DLSTM_OPTIONS,
        renderer="lstm-stream",
        shares_population=True,
        paper_table1=PaperRow(B=(6.97e-5, 87.16), K=(4.19e-6, 90.33), R=(1.11e-7, 90.59), Aver=89.36),
    )
)
register(
    Method(
        "dlstm-ssa",
        "trainer.dlstm.compensators:RecursiveDLSTMWithSSA",
        RECURSIVE,
        DLSTM_OPTIONS,
        renderer="lstm-stream",
        shares_population=True,
        paper_table1=PaperRow(B=(6.33e-5, 88.35), K=(3.39e-6, 92.16), R=(9.40e-8, 92.05), Aver=90.85),
    )
)
register(
    Method(
        "dlstm-issa",
        "trainer.dlstm.compensators:RecursiveDLSTMWithISSA",
        RECURSIVE,
        DLSTM_OPTIONS,
        renderer="lstm-stream",
        shares_population=True,
        paper_table1=PaperRow(B=(2.77e-5, 94.89), K=(1.14e-6, 97.37), R=(2.63e-8, 97.77), Aver=96.68),
    )
)
register(
    Method(
        PLA,
        "trainer.baselines.pla:PiecewiseLinear",
        MEMORYLESS,
        PLA_OPTIONS,
        renderer=PLA,
        paper_table1=PaperRow(B=(5.25e-4, 3.29), K=(3.45e-5, 20.23), R=(8.24e-7, 30.31), Aver=17.94),
        min_temp_span_c=10.0,  # 10 intervals of at least 1 degC each at the paper's setting
    )
)
register(
    Method(
        CUBIC,
        "trainer.baselines.poly3:CubicPolynomial",
        MEMORYLESS,
        POLY3_OPTIONS,
        renderer="cubic",
        min_temp_span_c=10.0,  # ArduPilot's TEMP_RANGE_MIN for the same cubic (AP_InertialSensor_tempcal.cpp)
    )
)
register(
    Method(
        DLSTM_TEMP,
        "trainer.dlstm.compensators:TemperatureDLSTM",
        TEMPERATURE_DRIVEN,
        DLSTM_OPTIONS,
        renderer="lstm-stream",
        min_temp_span_c=10.0,  # a network of the temperature alone: no span, no shape to learn
    )
)
register(
    Method(
        PHYSICS,
        "trainer.greybox.compensator:PhysicsCompensator",
        TEMPERATURE_DRIVEN,
        PHYSICS_OPTIONS,
        renderer=PHYSICS_RENDERER,
        min_temp_span_c=10.0,  # its backbone is the flight stacks' cubic (as poly3)
    )
)
register(
    Method(
        "persistence",
        "trainer.dlstm.compensators:Persistence",
        RECURSIVE,
        renderer="mean-stream",
        reference=True,
    )
)
