"""PX4 applies the thermal offset of a temperature up to 1 degC old: what that costs.

``TemperatureCompensation::update_offsets_accel`` (likewise ``_gyro``, ``_baro``) computes the
offset at each poll but reports it for publication only when ``fabsf(temperature -
last_temperature) > 1.0f``, and only then updates ``last_temperature`` (initially -100 degC,
``PerSensorData::reset_temperature``). So between publications the sensor is corrected with the
cubic evaluated at the temperature of the last publication: the correction lags in steps of just
over 1 degC. (A publication triggered by another sensor carries this sensor's fresh offset too, so
per sensor this is the worst case.)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from codegen.flightparams import TO_STACK_UNIT, ChannelCubic, cubic_extremes, group_by_instance
from trainer.data.channels import UNIT_LABELS

REPUBLISH_STEP_C = 1.0  # the "> 1.0f" in update_offsets_accel/_gyro/_baro
NEVER_PUBLISHED_C = -100.0  # PerSensorData's last_temperature before the first publication


def republished_temperature(temp_c: np.ndarray) -> np.ndarray:
    """For each sample, the temperature at which PX4 evaluated the offset it applies then."""
    applied = np.empty(len(temp_c))
    last = NEVER_PUBLISHED_C
    for i, temp in enumerate(np.asarray(temp_c, dtype=float)):
        if abs(temp - last) > REPUBLISH_STEP_C:
            last = temp
        applied[i] = last
    return applied


def republish_error(drift: Callable[[np.ndarray], np.ndarray], temp_c: np.ndarray) -> np.ndarray:
    """Applied minus exact correction, sample by sample (``drift``: the clamped cubic, any unit)."""
    temp = np.asarray(temp_c, dtype=float)
    return drift(republished_temperature(temp)) - drift(temp)


def lag_bound(cubic: ChannelCubic, lo_c: float, hi_c: float) -> float:
    """The most a 1 degC-old offset can differ from the exact one over the clamp range ``lo_c .. hi_c``
    (the steepest slope there times 1 degC; data-independent), in the model's unit."""
    low, high = cubic_extremes(cubic, lo_c, hi_c, order=1)
    return max(abs(low), abs(high)) * REPUBLISH_STEP_C / TO_STACK_UNIT[cubic.channel.unit]


def lag_bound_lines(channels: Sequence[ChannelCubic]) -> list[str]:
    """One line per channel for the export's summary: :func:`lag_bound` over its set's clamp range."""
    lines = []
    for group in group_by_instance(channels):
        for cubic in group.axes.values():
            unit = UNIT_LABELS[cubic.channel.unit]
            lines.append(
                f"{cubic.name}: PX4 updates the applied offset after > {REPUBLISH_STEP_C:g} degC of change: up "
                f"to {lag_bound(cubic, group.t_min_c, group.t_max_c):.3g} {unit} off the exact cubic (its "
                f"steepest slope x {REPUBLISH_STEP_C:g} degC)"
            )
    return lines
