"""The catalogue's bias effects: parameter registry and one formula per identifier.

Identifiers, parameter names and units are the contract of ``shared/specs/physics-catalogue.md``;
the mismatch finder calls :func:`effect_contribution` and :func:`drift` with the same names, so a
fitted effect and a simulated one are evaluated by the same code.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from trainer.physics.thermal import lowpass, play_operator

T_REF_C = 25.0


@dataclass(frozen=True)
class Param:
    """One parameter of an effect or noise term.

    ``rule`` is ``finite``, ``positive`` (> 0) or ``nonnegative`` (>= 0). ``default`` is used when
    the key is absent; a parameter with neither ``default`` nor ``optional`` is required.
    """

    name: str
    rule: str = "finite"
    default: float | None = None
    optional: bool = False


# Catalogue order: configs are written back in this order, so the order is part of equality.
EFFECT_PARAMETERS: dict[str, tuple[Param, ...]] = {
    "bias_poly": (
        Param("c0_mg", default=0.0),
        Param("c1_mg_per_c", default=0.0),
        Param("c2_mg_per_c2", default=0.0),
        Param("c3_mg_per_c3", default=0.0),
    ),
    "thermal_lag": (Param("tau_s", "positive"),),
    "temp_rate": (Param("k_mg_per_c_per_min"),),
    "hysteresis": (Param("amp_mg"), Param("width_c", "positive")),
    "stress_relaxation": (Param("gain_mg_per_c"), Param("tau_s", "positive")),
    "warmup": (Param("amp_mg"), Param("tau_s", "positive")),
    "periodic": (Param("amp_mg"), Param("period_s", "positive"), Param("phase_rad", default=0.0)),
    "bias_step": (Param("t_s", "nonnegative"), Param("step_mg")),
    "temp_quantization": (Param("lsb_c", "positive"),),
    "scale_factor_tc": (Param("sf_ppm_per_c"), Param("g_in_mg", optional=True)),
}

# Effects that may appear several times ([[effects.periodic]]); the others at most once.
MULTI_INSTANCE: frozenset[str] = frozenset({"periodic", "bias_step"})

# Effects that act on the temperature chain instead of adding a bias term.
TEMPERATURE_CHAIN: frozenset[str] = frozenset({"thermal_lag", "temp_quantization"})


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


def _dt(t: np.ndarray) -> float:
    """Mean sample period; the low-pass assumes uniform sampling (recordings allow 1 % jitter)."""
    if t.size < 2:
        raise ValueError("need at least two samples")
    return float(t[-1] - t[0]) / (t.size - 1)


def proof_mass_temperature(t: np.ndarray, T_die: np.ndarray, thermal_lag_tau_s: float | None) -> np.ndarray:
    """``T_pm = LP(T_die, tau_s)`` when ``thermal_lag`` is present, else ``T_die`` itself."""
    T_die = np.asarray(T_die, dtype=np.float64)
    if thermal_lag_tau_s is None:
        return T_die
    return lowpass(T_die, thermal_lag_tau_s, _dt(np.asarray(t)))


def quantize_temperature(temp_c: np.ndarray, lsb_c: float) -> np.ndarray:
    """``temp_quantization``: round to the nearest multiple of ``lsb_c`` (ties to even)."""
    return lsb_c * np.round(np.asarray(temp_c, dtype=np.float64) / lsb_c)


def rate_c_per_min(t: np.ndarray, T_die: np.ndarray) -> np.ndarray:
    """Numerical ``dT_die/dt`` in degC/min (central differences) for callers without the LP state."""
    return np.gradient(np.asarray(T_die, dtype=np.float64), np.asarray(t, dtype=np.float64)) * 60.0


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
    ``thermal_lag`` and ``temp_quantization`` are not additive (see :func:`drift`) and raise.
    """
    t = np.asarray(t, dtype=np.float64)
    T_die = np.asarray(T_die, dtype=np.float64)
    T_pm = np.asarray(T_pm, dtype=np.float64)
    p = params
    if identifier == "bias_poly":
        T_b = T_pm if play_width_c is None else play_operator(T_pm, play_width_c)
        d = T_b - T_REF_C
        coeffs = (p["c0_mg"], p["c1_mg_per_c"], p["c2_mg_per_c2"], p["c3_mg_per_c3"])
        return coeffs[0] + d * (coeffs[1] + d * (coeffs[2] + d * coeffs[3]))
    if identifier == "temp_rate":
        rate = rate_c_per_min(t, T_die) if dT_die_dt_c_per_min is None else dT_die_dt_c_per_min
        return p["k_mg_per_c_per_min"] * np.asarray(rate, dtype=np.float64)
    if identifier == "hysteresis":
        half = p["width_c"] / 2.0
        return p["amp_mg"] * (T_pm - play_operator(T_pm, p["width_c"])) / half
    if identifier == "stress_relaxation":
        return p["gain_mg_per_c"] * (T_die - lowpass(T_die, p["tau_s"], _dt(t)))
    if identifier == "warmup":
        return p["amp_mg"] * np.exp(-t / p["tau_s"])
    if identifier == "periodic":
        return p["amp_mg"] * np.sin(2.0 * np.pi * t / p["period_s"] + p["phase_rad"])
    if identifier == "bias_step":
        return np.where(t >= p["t_s"], p["step_mg"], 0.0)
    if identifier == "scale_factor_tc":
        g = p.get("g_in_mg", g_in_mg)
        if g is None:
            raise ValueError("scale_factor_tc needs g_in_mg (parameter or argument)")
        return np.asarray(g, dtype=np.float64) * 1e-6 * p["sf_ppm_per_c"] * (T_pm - T_REF_C)
    if identifier in TEMPERATURE_CHAIN:
        raise ValueError(f"{identifier} acts on the temperature chain, not additively; use drift()")
    raise ValueError(f"unknown effect identifier {identifier!r}")


def drift(
    effects: Iterable[EffectConfig],
    t: np.ndarray,
    T_die: np.ndarray,
    *,
    g_in_mg: np.ndarray | float = 0.0,
    dT_die_dt_c_per_min: np.ndarray | None = None,
) -> DriftBreakdown:
    """Everything deterministic that is not the true input, for a set of effects.

    Applies the temperature chain first (``thermal_lag`` gives ``T_pm``; ``hysteresis`` switches
    ``bias_poly`` to the play output), then sums the additive effects. ``temp_quantization``
    only touches the thermometer column, so it contributes nothing here.
    """
    effects = list(effects)
    lag = [e for e in effects if e.identifier == "thermal_lag"]
    T_pm = proof_mass_temperature(t, T_die, lag[0].params["tau_s"] if lag else None)
    hyst = [e for e in effects if e.identifier == "hysteresis"]
    width = hyst[0].params["width_c"] if hyst else None
    parts: list[tuple[str, np.ndarray]] = []
    total = np.zeros(np.shape(T_die))
    for effect in effects:
        if effect.identifier in TEMPERATURE_CHAIN:
            continue
        part = effect_contribution(
            effect.identifier,
            effect.params,
            t,
            T_die,
            T_pm,
            g_in_mg=g_in_mg,
            dT_die_dt_c_per_min=dT_die_dt_c_per_min,
            play_width_c=width,
        )
        part = np.broadcast_to(part, total.shape)
        parts.append((effect.identifier, part))
        total = total + part
    return DriftBreakdown(total=total, T_pm=T_pm, parts=parts)
