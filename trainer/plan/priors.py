"""What to identify: catalogue effects with prior ranges, and the draws of a Monte Carlo.

Four sources, one result (a tuple of :class:`Prior`): the sizes measured on the bundled real run
(:data:`MEASURED`, the default, per channel unit), an effect list on the command line
(``thermal_lag:tau_s=90..150,temp_rate:k_mg_per_c_per_min=0.4..1``) or a file: a TOML of the same
tables, a ``trainer diagnose --json`` document whose ambiguous and not-identifiable compensable
effects become the targets, or a fitted physics model (``model.pt``) whose effects become targets
around their fitted sizes. Parameters are named as the channel names them (``amp_dps`` on a
gyroscope) on input and output, and held under the catalogue's names inside.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trainer.errors import UserError
from trainer.greybox.terms import NEEDS_POWER_ON_TIME, STREAMABLE
from trainer.physics.catalogue import EFFECT_PARAMETERS, EFFECTS, excluded
from trainer.physics.catalogue.hysteresis_offset import DEFINITION as BRANCH_OFFSET
from trainer.physics.catalogue.temp_rate import DEFINITION as TEMP_RATE
from trainer.physics.catalogue.thermal_lag import DEFINITION as THERMAL_LAG
from trainer.physics.catalogue.units import CATALOGUE_UNIT, catalogue_names, channel_param_name
from trainer.physics.effects import EffectConfig

Range = tuple[float, float]

# The temperature-history effects measured on the bundled real chamber run (shared/data/real,
# tofupilot drone-board IMU; docs/real-data.md, docs/physics-method.md, trainer/physics/realistic.toml):
# lag: y axis tau_s = 116 +- 9 s; rate: z axis k = 0.40 mg per degC/min through a 30 s filter, y axis
# 1.0 through 280 s; branch offset: y and z axes 2.3 to 8.2 mg over play widths of 32 to 47 degC.
BUNDLED_RUN: dict[str, dict[str, Range]] = {
    THERMAL_LAG.identifier: {"tau_s": (90.0, 150.0)},
    TEMP_RATE.identifier: {"k_mg_per_c_per_min": (0.4, 1.0), "tau_s": (30.0, 280.0)},
    BRANCH_OFFSET.identifier: {"amp_mg": (2.3, 8.2), "width_c": (32.0, 47.0)},
}
# The same effects on the bundled run's gyro x (deg/s, held under the catalogue's names; sources in
# trainer/physics/realistic.toml's [channels.gyro0_x]): rate k = -0.117 +- 0.012 deg/s per degC/min
# through 330 +- 55 s, branch offset -0.056 +- 0.005 deg/s; the lag and the offset's width are not
# determined by that run, so their ranges are the simulated gyroscope's (60 s, 20 degC) widened.
BUNDLED_GYRO: dict[str, dict[str, Range]] = {
    THERMAL_LAG.identifier: {"tau_s": (40.0, 90.0)},
    TEMP_RATE.identifier: {"k_mg_per_c_per_min": (-0.141, -0.093), "tau_s": (220.0, 440.0)},
    BRANCH_OFFSET.identifier: {"amp_mg": (-0.066, -0.046), "width_c": (15.0, 30.0)},
}
MEASURED: dict[str, dict[str, dict[str, Range]]] = {CATALOGUE_UNIT: BUNDLED_RUN, "dps": BUNDLED_GYRO}
# A fitted model's effect becomes a target from (1 - MODEL_SPREAD) to (1 + MODEL_SPREAD) times its size.
MODEL_SPREAD = 0.3
# What a planned program may target: what the physics compensator models without a power-on clock.
PLANNABLE: tuple[str, ...] = tuple(name for name in STREAMABLE if name not in NEEDS_POWER_ON_TIME)


@dataclass(frozen=True)
class Prior:
    """One target effect: each parameter drawn uniformly from its range (``lo == hi``: fixed)."""

    identifier: str
    ranges: Mapping[str, Range]  # catalogue parameter names, values in the channel's unit
    unit: str = CATALOGUE_UNIT  # the channel's unit suffix (mg, dps, pa)

    @property
    def checked(self) -> tuple[str, ...]:
        """The parameters that must be recovered: the catalogue's own list (its test bench's)."""
        scenario = EFFECTS[self.identifier].scenario
        listed = scenario.checked if scenario is not None else ()
        return tuple(name for name in listed if name in self.ranges) or tuple(self.ranges)

    @property
    def centre(self) -> EffectConfig:
        return EffectConfig(self.identifier, {k: 0.5 * (lo + hi) for k, (lo, hi) in self.ranges.items()})

    def draw(self, rng: np.random.Generator) -> EffectConfig:
        return EffectConfig(
            self.identifier, {k: float(rng.uniform(lo, hi)) for k, (lo, hi) in self.ranges.items()}
        )

    def describe(self) -> str:
        return f"{self.identifier} " + ", ".join(
            f"{channel_param_name(k, self.unit)} {lo:g}" + ("" if hi == lo else f"..{hi:g}")
            for k, (lo, hi) in self.ranges.items()
        )


def draw_effects(priors: tuple[Prior, ...], rng: np.random.Generator) -> tuple[EffectConfig, ...]:
    return tuple(prior.draw(rng) for prior in priors)


def _check(identifier: str, given: Mapping[str, Range], where: str, unit: str = CATALOGUE_UNIT) -> Prior:
    """The prior of ``given`` ranges, named as the channel of ``unit`` names them, after checking them."""
    if identifier not in EFFECTS:
        raise UserError(f"{where}: unknown effect {identifier!r}; choose from {', '.join(PLANNABLE)}")
    if identifier not in PLANNABLE:
        raise UserError(
            f"{where}: {identifier} is not a drift the physics compensator models from temperature alone; "
            f"choose from {', '.join(PLANNABLE)}"
        )
    spec = {p.name: p for p in EFFECT_PARAMETERS[identifier]}
    names = catalogue_names(spec.values(), unit)
    ranges: dict[str, Range] = {}
    for shown, bounds in given.items():
        if shown not in names:
            raise UserError(f"{where}: {identifier} has no parameter {shown!r} (it has {', '.join(names)})")
        ranges[names[shown]] = bounds
    for name, (lo, hi) in ranges.items():
        shown = channel_param_name(name, unit)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            raise UserError(
                f"{where}: {identifier}.{shown} range {lo:g}..{hi:g} must be finite with low <= high"
            )
        rule = spec[name].rule
        if (rule == "positive" and lo <= 0) or (rule == "nonnegative" and lo < 0):
            raise UserError(f"{where}: {identifier}.{shown} must be {rule}, got a range from {lo:g}")
    missing = [
        channel_param_name(p.name, unit)
        for p in spec.values()
        if p.default is None and not p.optional and p.name not in ranges
    ]
    if missing:
        raise UserError(f"{where}: {identifier} needs a range for {', '.join(missing)}")
    return Prior(identifier, ranges, unit)


def _checked_set(priors: list[Prior], where: str) -> tuple[Prior, ...]:
    names = [p.identifier for p in priors]
    if not names:
        raise UserError(f"{where}: no target effect")
    if len(set(names)) != len(names):
        raise UserError(f"{where}: an effect is listed twice")
    for i, first in enumerate(names):
        for second in names[i + 1 :]:
            if excluded(first, second):
                raise UserError(f"{where}: {first} and {second} describe the same physics twice; keep one")
    return tuple(priors)


def measured(unit: str = CATALOGUE_UNIT, where: str = "targets") -> dict[str, dict[str, Range]]:
    """The bundled run's measured sizes on a channel of ``unit`` (catalogue names)."""
    if unit not in MEASURED:
        raise UserError(
            f"{where}: no measured sizes for a {unit} channel; give --effects or --targets with ranges"
        )
    return MEASURED[unit]


def bundled(unit: str = CATALOGUE_UNIT) -> tuple[Prior, ...]:
    return tuple(Prior(name, dict(ranges), unit) for name, ranges in measured(unit).items())


def _number(text: str, where: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise UserError(f"{where}: {text!r} is not a number") from None


def parse_spec(text: str, where: str = "--effects", unit: str = CATALOGUE_UNIT) -> tuple[Prior, ...]:
    """``effect:param=lo..hi:param=value,effect2`` (an effect alone takes the bundled run's ranges)."""
    priors = []
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        identifier, *assignments = (p.strip() for p in item.split(":"))
        ranges: dict[str, Range] = {}
        if not assignments and identifier in MEASURED.get(unit, {}):
            ranges = {channel_param_name(k, unit): v for k, v in MEASURED[unit][identifier].items()}
        for assignment in assignments:
            name, sep, value = assignment.partition("=")
            if not sep:
                raise UserError(f"{where}: {assignment!r} is not param=low..high or param=value")
            lo_text, dots, hi_text = value.partition("..")
            lo = _number(lo_text, where)
            ranges[name.strip()] = (lo, _number(hi_text, where) if dots else lo)
        if not ranges and identifier in EFFECTS:
            raise UserError(f"{where}: {identifier} has no bundled prior; give {identifier}:param=low..high")
        priors.append(_check(identifier, ranges, where, unit))
    return _checked_set(priors, where)


def _range(value: Any, where: str) -> Range:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value), float(value)
    if (
        isinstance(value, list)
        and len(value) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    ):
        return float(value[0]), float(value[1])
    raise UserError(f"{where}: expected a number or [low, high], got {value!r}")


def load_toml(path: Path, unit: str = CATALOGUE_UNIT) -> tuple[Prior, ...]:
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{path}: cannot read targets: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{path}: invalid TOML: {exc}") from None
    priors = []
    for identifier, table in data.items():
        if not isinstance(table, dict):
            raise UserError(f"{path}: [{identifier}] must be a table of parameter ranges")
        ranges = {k: _range(v, f"{path}: [{identifier}] {k}") for k, v in table.items()}
        priors.append(_check(identifier, ranges, f"{path}: [{identifier}]", unit))
    return _checked_set(priors, str(path))


def from_diagnosis(path: Path, unit: str = CATALOGUE_UNIT) -> tuple[Prior, ...]:
    """The ambiguous and not-identifiable compensable effects of a diagnosis; their prior ranges are the
    bundled run's, else the catalogue's own test-bench sizes (a range from 0.5x to 2x its draw)."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        names = [n for a in doc["ambiguous"] for n in a["effects"]]
        names += [n["effect"] for n in doc["not_identifiable"]]
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UserError(f"{path}: cannot read the diagnosis: {exc}") from None
    except (KeyError, TypeError):
        raise UserError(
            f"{path}: not a diagnosis document (needs 'ambiguous' and 'not_identifiable'; trainer diagnose --json)"
        ) from None
    chosen: list[str] = []
    for name in dict.fromkeys(names):
        if name in PLANNABLE and not any(excluded(name, other) for other in chosen):
            chosen.append(name)
    if not chosen:
        raise UserError(
            f"{path}: no ambiguous or not-identifiable effect that a compensator models; give --effects"
        )
    return _checked_set([_check(n, _default_ranges(n, unit), str(path), unit) for n in chosen], str(path))


def diagnosis_channel(path: Path) -> str | None:
    """The channel a diagnosis document was made on, when it names one (every channel of a
    multi-channel recording does; a one-axis recording whose metadata name none leaves it out: the
    default channel). An unreadable document is :func:`from_diagnosis`'s to refuse."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    channel = doc.get("channel") if isinstance(doc, dict) else None
    name = channel.get("name") if isinstance(channel, dict) else None
    return name if isinstance(name, str) else None


def _default_ranges(identifier: str, unit: str) -> dict[str, Range]:
    """The bundled run's range on this unit, else 0.5x to 2x the catalogue's test-bench size (mg only)."""
    ranges = MEASURED.get(unit, {}).get(identifier)
    scenario = EFFECTS[identifier].scenario
    if ranges is None and unit == CATALOGUE_UNIT and scenario is not None and scenario.draw is not None:
        typical = scenario.draw(np.random.default_rng(0), 3600.0, 1.0)
        ranges = {k: _spread(v, 0.5, 2.0) for k, v in typical.items()}
    if ranges is None:
        raise UserError(
            f"targets: no prior size for {identifier} on a {unit} channel; give --effects with ranges"
        )
    return {channel_param_name(k, unit): v for k, v in ranges.items()}


def _spread(value: float, low: float, high: float) -> Range:
    """``low`` to ``high`` times ``value``, ordered (a negative size keeps its sign)."""
    return (low * value, high * value) if value >= 0 else (high * value, low * value)


@dataclass(frozen=True)
class FittedModel:
    """What a fitted physics model says about the sensor to plan for."""

    priors: tuple[Prior, ...]
    channel: str | None  # the channel it was fitted on (None: a one-axis accelerometer recording)
    unit: str
    bias_poly: EffectConfig | None  # its temperature polynomial, the simulated sensor's own


def from_model(path: Path) -> FittedModel:
    """A physics model's plannable effects as targets, each parameter from (1 - MODEL_SPREAD) to
    (1 + MODEL_SPREAD) times its fitted value, on the channel it was fitted on."""
    from trainer.checkpoint import load_model
    from trainer.data.channels import unit_of_channel_name
    from trainer.greybox.compensator import PhysicsCompensator
    from trainer.physics.catalogue.bias_poly import DEFINITION as BIAS_POLY
    from trainer.train_stats import TrainStats

    model, checkpoint = load_model(path)
    if not isinstance(model, PhysicsCompensator):
        raise UserError(
            f"{path}: a {checkpoint['method']} model has no catalogue effects to plan for; "
            "give a physics model (trainer fit --method physics)"
        )
    channel = TrainStats.of_checkpoint(checkpoint).channel
    unit = unit_of_channel_name(channel)
    found = [e for e in model.effects if e.identifier in PLANNABLE]
    if not found:
        named = ", ".join(e.identifier for e in model.effects) or "none"
        raise UserError(
            f"{path}: the model names no effect a program can target (it has: {named}); "
            "give --effects to plan for one it has not found"
        )
    priors = [
        _check(
            e.identifier,
            {
                channel_param_name(k, unit): _spread(v, 1 - MODEL_SPREAD, 1 + MODEL_SPREAD)
                for k, v in e.params.items()
            },
            str(path),
            unit,
        )
        for e in found
    ]
    bias = next((e for e in model.effects if e.identifier == BIAS_POLY.identifier), None)
    return FittedModel(_checked_set(priors, str(path)), channel, unit, bias)


def load(path: str | None, spec: str | None, unit: str = CATALOGUE_UNIT) -> tuple[Prior, ...]:
    """The targets of ``--targets`` (TOML or diagnosis JSON) or ``--effects``; default: the bundled run's
    on a channel of ``unit`` (a model file goes through :func:`from_model`)."""
    if path is not None and spec is not None:
        raise UserError("--targets and --effects both give the targets; give one")
    if spec is not None:
        return parse_spec(spec, unit=unit)
    if path is None:
        return bundled(unit)
    file = Path(path)
    if not file.is_file():
        raise UserError(
            f"--targets: {file}: no such file (a TOML of prior ranges, trainer diagnose --json or a physics model.pt)"
        )
    return from_diagnosis(file, unit) if file.suffix.lower() == ".json" else load_toml(file, unit)
