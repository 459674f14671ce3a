"""What to identify: catalogue effects with prior ranges, and the draws of a Monte Carlo.

Three sources, one result (a tuple of :class:`Prior`): the sizes measured on the bundled real run
(:data:`BUNDLED_RUN`, the default), an effect list on the command line
(``thermal_lag:tau_s=90..150,temp_rate:k_mg_per_c_per_min=0.4..1``) or a file: a TOML of the same
tables, or a ``trainer diagnose --json`` document whose ambiguous and not-identifiable compensable
effects become the targets.
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
# What a planned program may target: what the physics compensator models without a power-on clock.
PLANNABLE: tuple[str, ...] = tuple(name for name in STREAMABLE if name not in NEEDS_POWER_ON_TIME)


@dataclass(frozen=True)
class Prior:
    """One target effect: each parameter drawn uniformly from its range (``lo == hi``: fixed)."""

    identifier: str
    ranges: Mapping[str, Range]

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
            f"{k} {lo:g}" + ("" if hi == lo else f"..{hi:g}") for k, (lo, hi) in self.ranges.items()
        )


def draw_effects(priors: tuple[Prior, ...], rng: np.random.Generator) -> tuple[EffectConfig, ...]:
    return tuple(prior.draw(rng) for prior in priors)


def _check(identifier: str, ranges: Mapping[str, Range], where: str) -> Prior:
    if identifier not in EFFECTS:
        raise UserError(f"{where}: unknown effect {identifier!r}; choose from {', '.join(PLANNABLE)}")
    if identifier not in PLANNABLE:
        raise UserError(
            f"{where}: {identifier} is not a drift the physics compensator models from temperature alone; "
            f"choose from {', '.join(PLANNABLE)}"
        )
    spec = {p.name: p for p in EFFECT_PARAMETERS[identifier]}
    for name, (lo, hi) in ranges.items():
        if name not in spec:
            raise UserError(f"{where}: {identifier} has no parameter {name!r} (it has {', '.join(spec)})")
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            raise UserError(
                f"{where}: {identifier}.{name} range {lo:g}..{hi:g} must be finite with low <= high"
            )
        rule = spec[name].rule
        if (rule == "positive" and lo <= 0) or (rule == "nonnegative" and lo < 0):
            raise UserError(f"{where}: {identifier}.{name} must be {rule}, got a range from {lo:g}")
    missing = [p.name for p in spec.values() if p.default is None and not p.optional and p.name not in ranges]
    if missing:
        raise UserError(f"{where}: {identifier} needs a range for {', '.join(missing)}")
    return Prior(identifier, dict(ranges))


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


def bundled() -> tuple[Prior, ...]:
    return tuple(Prior(name, dict(ranges)) for name, ranges in BUNDLED_RUN.items())


def _number(text: str, where: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise UserError(f"{where}: {text!r} is not a number") from None


def parse_spec(text: str, where: str = "--effects") -> tuple[Prior, ...]:
    """``effect:param=lo..hi:param=value,effect2`` (an effect alone takes the bundled run's ranges)."""
    priors = []
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        identifier, *assignments = (p.strip() for p in item.split(":"))
        ranges: dict[str, Range] = dict(BUNDLED_RUN.get(identifier, {})) if not assignments else {}
        for assignment in assignments:
            name, sep, value = assignment.partition("=")
            if not sep:
                raise UserError(f"{where}: {assignment!r} is not param=low..high or param=value")
            lo_text, dots, hi_text = value.partition("..")
            lo = _number(lo_text, where)
            ranges[name.strip()] = (lo, _number(hi_text, where) if dots else lo)
        if not ranges and identifier in EFFECTS:
            raise UserError(f"{where}: {identifier} has no bundled prior; give {identifier}:param=low..high")
        priors.append(_check(identifier, ranges, where))
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


def load_toml(path: Path) -> tuple[Prior, ...]:
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
        priors.append(_check(identifier, ranges, f"{path}: [{identifier}]"))
    return _checked_set(priors, str(path))


def from_diagnosis(path: Path) -> tuple[Prior, ...]:
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
    return _checked_set([_check(n, _default_ranges(n), str(path)) for n in chosen], str(path))


def _default_ranges(identifier: str) -> dict[str, Range]:
    if identifier in BUNDLED_RUN:
        return dict(BUNDLED_RUN[identifier])
    scenario = EFFECTS[identifier].scenario
    if scenario is None or scenario.draw is None:
        return {}
    typical = scenario.draw(np.random.default_rng(0), 3600.0, 1.0)
    return {k: (0.5 * v, 2.0 * v) if v > 0 else (2.0 * v, 0.5 * v) for k, v in typical.items()}


def load(path: str | None, spec: str | None) -> tuple[Prior, ...]:
    """The targets of ``--targets`` (TOML or diagnosis JSON) or ``--effects``; default: the bundled run's."""
    if path is not None and spec is not None:
        raise UserError("--targets and --effects both give the targets; give one")
    if spec is not None:
        return parse_spec(spec)
    if path is None:
        return bundled()
    file = Path(path)
    if not file.is_file():
        raise UserError(
            f"--targets: {file}: no such file (a TOML of prior ranges or trainer diagnose --json)"
        )
    return from_diagnosis(file) if file.suffix.lower() == ".json" else load_toml(file)
