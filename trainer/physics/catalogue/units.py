"""Catalogue parameters on a channel whose unit is not mg (a gyroscope, a barometer).

``shared/specs/physics-catalogue.md``, "Other channels": the same effects and noise terms describe
any channel's bias; an amplitude parameter carries the channel's unit in place of ``mg``
(``amp_mg`` -> ``amp_dps``, ``k_mg_per_c_per_min`` -> ``k_dps_per_c_per_min``), time, temperature
and width parameters keep their names, identifiers never change. Inside the tool parameters keep
their catalogue (mg) names, because the one-channel view carries any unit in its ``accel_mg``
column; :func:`channel_param_name` is the one renaming, applied where a name is shown or read
(JSON, reports, TOML, fit summaries, the physics model file).

Plausible amplitude ranges are in mg and fit no gyroscope or barometer, so on another unit an
amplitude is judged against the channel's own drift instead (:func:`plausible_range`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from trainer.physics.catalogue.base import Param

CATALOGUE_UNIT = "mg"  # the unit the catalogue's parameter names and plausible ranges are written in


def channel_param_name(name: str, unit: str) -> str:
    """The name of catalogue parameter ``name`` on a channel of unit suffix ``unit`` (mg, dps, pa)."""
    if unit == CATALOGUE_UNIT:
        return name
    return "_".join(unit if part == CATALOGUE_UNIT else part for part in name.split("_"))


def channel_params(params: Mapping[str, float], unit: str) -> dict[str, float]:
    """Catalogue-named parameters as the channel names them (same order)."""
    return {channel_param_name(name, unit): value for name, value in params.items()}


def catalogue_names(spec: Iterable[Param], unit: str) -> dict[str, str]:
    """``{name on the channel: catalogue name}`` for the parameters ``spec`` (to read a channel's TOML)."""
    return {channel_param_name(p.name, unit): p.name for p in spec}


def is_amplitude(name: str) -> bool:
    """Whether a catalogue parameter is in the sensor's unit (its name carries ``mg``)."""
    return CATALOGUE_UNIT in name.split("_")


@dataclass(frozen=True)
class ChannelScale:
    """What a non-mg channel's amplitudes are judged against: its cubic drift over the run.

    ``drift_span`` is max - min of a cubic in temperature fitted to the channel (channel unit);
    a per-degC amplitude is judged over ``temp_span_c``, a per-(degC/min) one at
    ``ramp_rate_c_per_min``, the 95th percentile of ``|dT/dt|`` (the ramps' rate, not a reversal's spike).
    """

    unit: str
    drift_span: float
    temp_span_c: float
    ramp_rate_c_per_min: float

    @classmethod
    def measure(
        cls, unit: str, temp_c: np.ndarray, value: np.ndarray, rate_c_per_min: np.ndarray
    ) -> ChannelScale:
        """The scale of a recording (block means are enough: the cubic is smooth)."""
        temp = np.asarray(temp_c, dtype=np.float64)
        centre = 0.5 * (float(temp.min()) + float(temp.max()))
        coeffs = np.polyfit(temp - centre, np.asarray(value, dtype=np.float64), 3)
        cubic = np.polyval(coeffs, temp - centre)
        return cls(
            unit,
            float(np.ptp(cubic)),
            float(np.ptp(temp)),
            float(np.percentile(np.abs(rate_c_per_min), 95)) if np.size(rate_c_per_min) else 0.0,
        )

    def per(self, name: str) -> float:
        """What one unit of amplitude parameter ``name`` is multiplied by in the drift (0: unknown)."""
        after = name.split("_")[name.split("_").index(CATALOGUE_UNIT) + 1 :]
        return {
            (): 1.0,
            ("per", "c"): self.temp_span_c,
            ("per", "c", "per", "min"): self.ramp_rate_c_per_min,
        }.get(tuple(after), 0.0)


def judged_by_drift_span(name: str, scale: ChannelScale | None) -> bool:
    """Whether parameter ``name`` is judged against the channel's drift span (an amplitude on a
    channel whose unit is not mg) rather than the catalogue's range."""
    return scale is not None and scale.unit != CATALOGUE_UNIT and is_amplitude(name)


def plausible_range(param: Param, scale: ChannelScale | None) -> tuple[float, float] | None:
    """The plausible range of ``|value|`` the finder flags against (None: not flagged).

    Time, temperature and width parameters: the catalogue's range. An amplitude is implausible
    only when too large: on an mg channel (``scale`` None or in mg) above the catalogue's range, on
    another unit when its contribution over the run exceeds the channel's cubic drift span
    (catalogue, "Other channels"): ``0 .. span / per``. The lower ends of the catalogue's amplitude
    ranges are typical sizes, not physical limits: on a quiet sensor a smaller effect with the
    criterion's evidence is real (a 0.012 mg branch offset was once reported "implausible" and not
    named on a sensor with 0.01 mg of white noise).
    """
    if param.plausible is None or not param.flagged:
        return None
    if not is_amplitude(param.name):
        return param.plausible
    if not judged_by_drift_span(param.name, scale):
        return (0.0, param.plausible[1])
    assert scale is not None
    per = scale.per(param.name)
    return (0.0, scale.drift_span / per) if per > 0 else None
