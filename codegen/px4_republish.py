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
POLL_S = 1.0  # TemperatureCompensationModule checks at 1 Hz: the temperature moves on between checks
FAST_RATE_C_PER_MIN = 10.0  # the heating rate the export's summary quotes (a board warming at power-on)
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


def lag_bound(cubic: ChannelCubic, lo_c: float, hi_c: float, rate_c_per_min: float = 0.0) -> float:
    """The most the applied offset can differ from the exact one over the clamp range ``lo_c .. hi_c``
    while the temperature moves at up to ``rate_c_per_min``: the steepest slope there times the
    temperature it can lag, 1 degC plus what one poll interval adds (PX4 checks the 1 degC at each
    1 Hz poll, and the samples between polls are corrected with the last published offset), in the
    model's unit."""
    low, high = cubic_extremes(cubic, lo_c, hi_c, order=1)
    lag_c = REPUBLISH_STEP_C + abs(rate_c_per_min) / 60.0 * POLL_S
    return max(abs(low), abs(high)) * lag_c / TO_STACK_UNIT[cubic.channel.unit]


def lag_bound_lines(channels: Sequence[ChannelCubic]) -> list[str]:
    """One line per compensated channel for the export's summary: :func:`lag_bound` over its set's
    clamp range."""
    lines = []
    for group in group_by_instance(channels):
        for cubic in group.axes.values():
            unit = UNIT_LABELS[cubic.channel.unit]
            slow = lag_bound(cubic, group.t_min_c, group.t_max_c)
            fast = lag_bound(cubic, group.t_min_c, group.t_max_c, FAST_RATE_C_PER_MIN)
            if slow == 0.0 and fast == 0.0:  # the identity (or a constant): nothing lags
                continue
            lines.append(
                f"{cubic.name}: PX4 updates the applied offset after > {REPUBLISH_STEP_C:g} degC of change, checked "
                f"at {1 / POLL_S:g} Hz: up to {slow:.3g} {unit} off the exact cubic (its steepest slope x "
                f"{REPUBLISH_STEP_C:g} degC) plus the slope x the change between checks: {fast:.3g} {unit} while "
                f"the temperature moves {FAST_RATE_C_PER_MIN:g} degC/min"
            )
    return lines
