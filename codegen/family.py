"""THE list of C families: one :class:`CFamily` per renderer of ``trainer/methods.py``.

A C family is everything the code generator knows of one kind of model, found together in one
unit of ``codegen/families/``: its checkpoint parser, its quantiser, its golden (integer numpy)
model, its template and the template's variables, its manifest section and table sizes. Export,
verify and the IMU module dispatch through :func:`family_of` instead of testing model types.

Adding a family is one unit plus one line of :data:`UNITS` (or one :func:`register` call, as
``tests/export/test_codegen_family_registry.py`` does with a throwaway one). Units are named by import
path and imported on first use, so the stage modules (spec, quantize, render, manifest) can
dispatch here while the units build on them: no import cycle.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from trainer import methods as registry
from trainer.errors import UserError
from trainer.fields import DottedFields

# The contracts between the stage modules and the units (declared here, so that this module
# imports none of codegen: the stage modules import it).


class ModelSpec(Protocol):
    """A parsed model (each family's parser returns its own spec)."""

    @property
    def method(self) -> str: ...


class QuantModel(Protocol):
    """A quantised model (each family's quantiser returns its own; ``limits``: codegen.quantize.Limits)."""

    @property
    def method(self) -> str: ...

    @property
    def limits(self) -> Any: ...


class Golden(Protocol):
    """A golden model (codegen.golden.GoldenBase): the C's integer arithmetic in numpy."""

    flags: int
    samples: int
    input_clamped: np.ndarray  # per sample of the last run: an input was clamped (FLAG_INPUT_CLAMPED)

    def init(self) -> None: ...

    def reset(self) -> None: ...

    def run(self, accel: np.ndarray, temp: np.ndarray) -> np.ndarray: ...

    def state(self) -> dict[str, np.ndarray | int]: ...


# renderer name -> "module:ATTRIBUTE" of its CFamily, in the order of trainer/methods.py RENDERERS
UNITS: dict[str, str] = {
    "lstm-stream": "codegen.families.stream:LSTM",
    "mean-stream": "codegen.families.stream:MEAN",
    registry.PLA: "codegen.families.pla:FAMILY",
    "cubic": "codegen.families.cubic:FAMILY",
    registry.PHYSICS_RENDERER: "codegen.families.physics:FAMILY",
}


@dataclass(frozen=True)
class TimeBase:
    """A family built for one sample rate (codegen/rate.py): ``rate_hz`` of a quantised model,
    ``trained_hz`` of a raw checkpoint, ``retime``: the raw checkpoint re-derived for another rate
    (millihertz), ``what`` it re-derives (for the export's note)."""

    rate_hz: Callable[[Any], float]
    trained_hz: Callable[[dict[str, Any]], float]
    retime: Callable[[dict[str, Any], int], dict[str, Any]]
    what: str


@dataclass(frozen=True)
class ImuForm:
    """A family's channel of the IMU module (codegen/imu.py): ``kind``, its NAME_KIND_ number (the
    blob's) and ``code`` (the NAME_KIND_ suffix); ``tables``, the channel's record
    (codegen.imu_record.ChannelTables) given the model and the index of the sensor whose temperature it
    reads; ``label``: its channels in messages. The rest says what the module holds for it:
    ``snippets``: its template of macros, each filling one place of imu.h.j2 / imu.c.j2 (the macro of
    that name; a place it has no macro for gets nothing of it; in a module with ``NAME_restore``,
    ``c_identity``, ``c_saved_ok``, ``c_restore``, ``kept`` and ``bounds_doc`` keep its state, and
    a form with state but no ``c_restore`` starts afresh there, by its ``c_init`` and ``c_reset``);
    ``context``: that template's variables
    given its channels (codegen.imu_record.ImuPart); ``manifest``: its keys of the module's manifest;
    ``blob``: its record in the calibration blob after the channel header (None: built-in tables only);
    a family with a blob record is in every module (a blob may put it on any channel), the others only
    in a module with a channel of theirs; ``slots``: its tables and state are arrays indexed by the
    record's ``slot``; ``layout_tag``: its channels keep state, so the module id names them under this
    tag; ``timed``, ``timed_brief``: what the sample rate discretises (empty: memoryless)."""

    kind: int
    tables: Callable[[Any, int], Any]
    code: str
    label: str
    snippets: Path | None = None
    context: Callable[[Any], dict[str, object]] | None = None
    manifest: Callable[[Any], dict[str, object]] | None = None
    blob: Callable[[Any], bytes] | None = None
    slots: bool = False
    layout_tag: str = ""
    timed: str = ""
    timed_brief: str = ""


@dataclass(frozen=True)
class InputClamps:
    """Where a module's step clamps its inputs, each clamp setting ``NAME_FLAG_INPUT_CLAMPED``: the one
    declaration that the C template renders its clamps from (codegen/render.py gives the template
    ``temp_lo``/``temp_hi`` and ``signal_limit`` only when declared here) and that the manifest's
    ``input_limits``, the header and ``codegen verify`` state.

    ``temp_mdegc``: the temperature is clamped into [lo, hi] mdegC (None: it is not clamped; the
    model does not read it beyond the valid-range flag); ``signal_lsb``: the raw input (acceleration,
    angular rate, pressure) is clamped to +-signal_lsb before the model reads it (None: the model
    subtracts the drift from the raw input as it comes and never clamps it)."""

    temp_mdegc: tuple[int, int] | None
    signal_lsb: int | None = None


def front_end_temperature(model: Any) -> InputClamps:
    """The default: the temperature clamped to the front end's range (``Limits.temp_lo_mdegc`` ..
    ``temp_hi_mdegc``), the raw input never clamped."""
    return InputClamps((model.limits.temp_lo_mdegc, model.limits.temp_hi_mdegc))


def _no_state(model: Any, common: list[Any]) -> list[Any]:
    return common


@dataclass(frozen=True, eq=False)
class CFamily:
    """One C family. ``template``: its C template (included by ``module.c.j2`` for NAME_init, _reset
    and _step); ``context``: that template's variables (``macros``: its own NAME_ macros;
    ``network_step_field``: the state field that is 0 on the samples where a network steps, for the
    benchmark harness); ``state``: the state struct's members given the common ones (flags, samples);
    ``schedules``: the ``--schedule`` values it takes; ``kernels``: extra kernel headers shipped with
    its modules (manifest key -> file; each has a ``#define TDC..._VERSION N`` the module checks);
    ``restore``: it has NAME_restore (an IMU module with a channel of it has one too); ``usage``: its paragraph of the header's comment (a template
    beside ``template``; None: a memoryless model's, any rate); ``time_base``: None for a memoryless
    family (any rate); ``imu``: None when it has no IMU-module form; ``input_clamps``: where a model's
    step clamps its inputs (:class:`InputClamps`; the raw input only in a network whose input it is,
    to the limit of its unit, codegen/input_limits.py: the others subtract the drift from it as it comes)."""

    name: str
    parse: Callable[[DottedFields, DottedFields, str], ModelSpec]
    quantise: Callable[[Any, Any, str], QuantModel]  # (spec, codegen.quantize.Limits, schedule)
    golden: Callable[[Any], Golden]
    template: Path
    context: Callable[[Any], dict[str, object]]
    manifest: Callable[[Any], dict[str, object]]
    tables: Callable[[Any], dict[str, int]]
    state: Callable[[Any, list[Any]], list[Any]] = _no_state  # codegen.render.Field
    schedules: tuple[str, ...] = ("step",)
    kernels: dict[str, Path] = field(default_factory=dict)
    restore: bool = False
    usage: Path | None = None
    time_base: TimeBase | None = None
    imu: ImuForm | None = None
    input_clamps: Callable[[Any], InputClamps] = front_end_temperature


_LOADED: dict[str, CFamily] = {}


def register(family: CFamily) -> CFamily:
    """Add a family (a test's throwaway one); its name is the renderer a method names."""
    if family.name in UNITS or family.name in _LOADED:
        raise ValueError(f"C family {family.name!r} is registered already")
    _LOADED[family.name] = family
    return family


def unregister(name: str) -> None:
    """Remove a family added by :func:`register` (tests)."""
    if name in UNITS:
        raise ValueError(f"C family {name!r} is built in")
    del _LOADED[name]


def get(name: str) -> CFamily:
    """The family of renderer ``name`` (its unit imported on first use)."""
    if name not in _LOADED:
        if name not in UNITS:
            raise UserError(f"no C family {name!r} (known: {', '.join(names())})")
        module, _, attribute = UNITS[name].partition(":")
        _LOADED[name] = getattr(importlib.import_module(module), attribute)
    return _LOADED[name]


def names() -> tuple[str, ...]:
    """Every family: the built-in units, then the registered ones."""
    return (*UNITS, *(name for name in _LOADED if name not in UNITS))


def entries() -> Iterator[CFamily]:
    return iter(tuple(get(name) for name in names()))


def schedules() -> tuple[str, ...]:
    """Every ``--schedule`` value some family takes (its first family's order: "step" first)."""
    return tuple(dict.fromkeys(s for unit in entries() for s in unit.schedules))


def family_of(model: QuantModel | ModelSpec) -> CFamily:
    """The family of a parsed or quantised model (through its method's renderer)."""
    renderer = registry.get(model.method).renderer
    if renderer is None:
        raise UserError(f"method {model.method!r} has no code generator")
    return get(renderer)
