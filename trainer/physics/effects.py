"""The catalogue's bias effects evaluated together: the temperature chain, then the additive terms.

Each effect's parameters and formula live in its own module of :mod:`trainer.physics.catalogue`;
this module only applies them in the catalogue's order of evaluation. Identifiers, parameter
names and units are the contract of ``shared/specs/physics-catalogue.md``; the mismatch finder
calls :func:`effect_contribution` and :func:`drift` with the same names, so a fitted effect and a
simulated one are evaluated by the same code.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from trainer.physics.catalogue import EFFECT_PARAMETERS, EFFECTS, MULTI_INSTANCE, TEMPERATURE_CHAIN
from trainer.physics.catalogue.base import T_REF_C, Param, Signals, rate_c_per_min
from trainer.physics.thermal import play_operator

__all__ = [
    "EFFECT_PARAMETERS",
    "MULTI_INSTANCE",
    "TEMPERATURE_CHAIN",
    "T_REF_C",
    "DriftBreakdown",
    "EffectConfig",
    "Param",
    "drift",
    "effect_contribution",
    "rate_c_per_min",
]


@dataclass(frozen=True)
class EffectConfig:
    """One effect instance: a catalogue identifier and its parameters in catalogue units."""

    identifier: str
    params: dict[str, float] = field(default_factory=dict)


@dataclass
class DriftBreakdown:
    """The deterministic part of the output and the temperatures it was computed from.

    ``parts`` holds one array per additive effect instance, in configuration order; ``total`` is
    their sum (including the scale-factor term ``g_in * 1e-6 * sf * (T_pm - T_ref)``).
    """

    total: np.ndarray
    T_pm: np.ndarray
    parts: list[tuple[str, np.ndarray]]


def _additive(identifier: str, params: Mapping[str, float], signals: Signals) -> np.ndarray:
    definition = EFFECTS.get(identifier)
    if definition is None:
        raise ValueError(f"unknown effect identifier {identifier!r}")
    if definition.contribution is None:
        raise ValueError(f"{identifier} acts on the temperature chain, not additively; use drift()")
    return definition.contribution(params, signals)


def effect_contribution(
    identifier: str,
    params: Mapping[str, float],
    t: np.ndarray,
    T_die: np.ndarray,
    T_pm: np.ndarray,
    *,
    g_in_mg: np.ndarray | float | None = None,
    dT_die_dt_c_per_min: np.ndarray | None = None,
    play_width_c: float | None = None,
) -> np.ndarray:
    """Additive contribution (mg) of one effect instance, exactly as the catalogue writes it.

    ``play_width_c``: when ``hysteresis`` is present, ``bias_poly`` is evaluated on the play output
    of ``T_pm`` with that width (catalogue: ``T_b``). ``dT_die_dt_c_per_min`` defaults to the
    numerical derivative of ``T_die``; the simulator passes the analytic ``(S - T_die)/tau``.
    ``scale_factor_tc`` uses its own ``g_in_mg`` parameter when given, else ``g_in_mg``.
    Temperature-chain effects (``thermal_lag``, ``temp_quantization``) are not additive and raise.
    """
    signals = Signals(
        np.asarray(t, dtype=np.float64),
        np.asarray(T_die, dtype=np.float64),
        np.asarray(T_pm, dtype=np.float64),
        rate_c_per_min=dT_die_dt_c_per_min,
        g_in_mg=g_in_mg,
        poly_temperature=None if play_width_c is None else (lambda T: play_operator(T, play_width_c)),
    )
    return _additive(identifier, params, signals)


def check_instances(identifiers: Iterable[str]) -> None:
    """Several instances of an additive effect add their terms (a sum of branch offsets of several
    widths); an effect that changes a temperature the others read (a lag giving ``T_pm``, a play
    output the polynomial reads) is applied once by :func:`drift`, so a second instance would be
    ignored there and run side by side in the stream: refused (ValueError, one line)."""
    for identifier, n in Counter(identifiers).items():
        definition = EFFECTS[identifier]
        if n > 1 and (definition.proof_mass is not None or definition.bias_temperature is not None):
            raise ValueError(
                f"{identifier} appears {n} times; it changes a temperature the other effects read and may appear once"
            )


def drift(
    effects: Iterable[EffectConfig],
    t: np.ndarray,
    T_die: np.ndarray,
    *,
    g_in_mg: np.ndarray | float = 0.0,
    dT_die_dt_c_per_min: np.ndarray | None = None,
    play_start_c: float | None = None,
) -> DriftBreakdown:
    """Everything deterministic that is not the true input, for a set of effects.

    Applies the temperature chain first (``thermal_lag`` gives ``T_pm``; ``hysteresis`` switches
    what ``bias_poly`` reads to the play output), then sums the additive effects.
    ``temp_quantization`` only touches the thermometer column, so it contributes nothing here.
    ``play_start_c``: the branch effects' play operator state before the first sample
    (:class:`~trainer.physics.catalogue.base.Signals`; ``None``: the catalogue's half-way start).
    """
    effects = list(effects)
    t = np.asarray(t, dtype=np.float64)
    T_pm = np.asarray(T_die, dtype=np.float64)
    poly_temperature = None
    for effect in effects:
        definition = EFFECTS[effect.identifier]
        if definition.proof_mass is not None:
            T_pm = definition.proof_mass(t, T_pm, effect.params)
        if definition.bias_temperature is not None and poly_temperature is None:
            poly_temperature = (lambda f, p: lambda T: f(T, p, play_start_c))(
                definition.bias_temperature, effect.params
            )
    signals = Signals(
        t,
        np.asarray(T_die, dtype=np.float64),
        T_pm,
        rate_c_per_min=dT_die_dt_c_per_min,
        g_in_mg=g_in_mg,
        poly_temperature=poly_temperature,
        play_start_c=play_start_c,
    )
    parts: list[tuple[str, np.ndarray]] = []
    total = np.zeros(np.shape(T_die))
    for effect in effects:
        if effect.identifier in TEMPERATURE_CHAIN:
            continue
        part = _additive(effect.identifier, effect.params, signals)
        part = np.broadcast_to(part, total.shape)
        parts.append((effect.identifier, part))
        total = total + part
    return DriftBreakdown(total=total, T_pm=T_pm, parts=parts)
