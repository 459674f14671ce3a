"""ArduPilot's IMU temperature calibration (``INS_TCALn_*``): its convention, and undoing it on a log.

ArduPilot (``libraries/AP_InertialSensor/AP_InertialSensor_tempcal.cpp``, ``correct_sensor``)
corrects every IMU sample in the sensor frame *before* it is logged, when ``INS_TCALn_ENABLE`` is
1 (0 is off, 2 learns without correcting)::

    P(d) = (C1 + (C2 + C3 d) d) d * 1e-6        Ck = INS_TCALn_ACCk_X|Y|Z (GYRk_* for the gyroscope)
    T'   = clamp(T, INS_TCALn_TMIN, INS_TCALn_TMAX), likewise CALTEMP' (INS_ACCn_CALTEMP, INS_GYRn_CALTEMP)
    logged = raw - P(T' - 35) + P(CALTEMP' - 35)        m/s^2, rad/s

So the ``IMU`` messages of such a log hold the residual drift, and a fit of them exported as
``INS_TCAL`` would replace the real calibration with that residual. :func:`remove_correction` adds
the logged correction back; ``codegen export --format ardupilot-parm`` writes the same convention
from the constants declared here, so exporting a fit of the restored data reproduces the stack's
view. The ordinary calibration applied after it (``INS_ACCOFFS_*``, ``INS_ACC2OFFS_*``, ..., scale) is not undone: the
offset is a constant, and a scale of 1.001 changes the restored drift by 0.1 %.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trainer.errors import UserError

TEMP_REF_C = 35.0  # TEMP_REFERENCE in AP_InertialSensor_tempcal.cpp
TEMP_RANGE_C = (-70.0, 80.0)  # @Range of INS_TCALn_TMIN and INS_TCALn_TMAX in AP_InertialSensor_tempcal.cpp
SCALE = 1.0e6  # SCALE_FACTOR: the parameters hold the coefficients times 1e6
PREFIX = {"accel": "ACC", "gyro": "GYR"}  # INS_TCALn_ACCk_X, INS_TCALn_GYRk_X
INSTANCES = 3  # INS_TCAL1..3 correct IMU instances 0..2
ENABLED = 1.0  # INS_TCALn_ENABLE: 1 corrects (2 learns and does not)
ORDERS = (1, 2, 3)
AXES = ("X", "Y", "Z")


def set_prefix(instance: int) -> str:
    """``INS_TCAL1`` for IMU instance 0."""
    return f"INS_TCAL{instance + 1}"


def cal_temp_param(sensor: str, instance: int) -> str:
    """``INS_ACC1_CALTEMP``: the temperature the ordinary calibration of IMU ``instance`` was made at."""
    return f"INS_{PREFIX[sensor]}{instance + 1}_CALTEMP"


@dataclass(frozen=True)
class TcalSet:
    """The logged ``INS_TCALn`` set of one IMU instance (coefficients as stored, i.e. times 1e6)."""

    instance: int
    t_min_c: float
    t_max_c: float
    coefficients: dict[str, np.ndarray]  # sensor -> [order 1..3, axis x..z]
    cal_temp_c: dict[str, float]  # sensor -> CALTEMP

    def correction(self, sensor: str, temp_c: np.ndarray) -> np.ndarray:
        """What ArduPilot subtracted from each sample, ``P(T' - 35) - P(CALTEMP' - 35)``, shape (n, 3)."""

        def poly(t_c: np.ndarray) -> np.ndarray:
            d = np.clip(t_c, self.t_min_c, self.t_max_c)[:, None] - TEMP_REF_C
            c1, c2, c3 = self.coefficients[sensor]
            return (c1 + (c2 + c3 * d) * d) * d / SCALE

        return poly(np.asarray(temp_c, dtype=np.float64)) - poly(np.array([self.cal_temp_c[sensor]]))

    def describe(self) -> str:
        return (
            f"IMU {self.instance} was logged with {set_prefix(self.instance)}_ENABLE=1 (already compensated): "
            f"its correction ({self.t_min_c:g} .. {self.t_max_c:g} degC) was added back from the log's "
            f"parameters, so the fit sees the raw drift"
        )


def logged_tcal(
    params: dict[str, float], changed: set[str], instance: int, orientation: int, source: str
) -> TcalSet | None:
    """The enabled ``INS_TCALn`` set of IMU ``instance`` from the log's PARM values, else None.

    One line instead when it cannot be undone exactly: a parameter missing, changed during the
    log, or a board orientation (the correction is in the sensor frame, ``IMU`` in the vehicle's).
    """
    prefix = set_prefix(instance)
    if instance >= INSTANCES:
        return None
    if f"{prefix}_ENABLE" in changed:
        raise UserError(
            f"{source}: {prefix}_ENABLE changes during the log, so the IMU {instance} data are partly "
            f"corrected before logging; import a log recorded with fixed parameters"
        )
    if params.get(f"{prefix}_ENABLE") != ENABLED:
        return None
    where = f"{source}: {prefix}_ENABLE=1 (the IMU {instance} data were corrected before logging)"
    if orientation:
        raise UserError(
            f"{where} and AHRS_ORIENTATION={orientation}: the correction applies in the sensor frame and "
            f"the IMU messages are rotated after it, so it cannot be removed per axis; record with "
            f"{prefix}_ENABLE=0"
        )
    names = [f"{prefix}_TMIN", f"{prefix}_TMAX"]
    names += [cal_temp_param(sensor, instance) for sensor in PREFIX]
    names += [f"{prefix}_{short}{k}_{axis}" for short in PREFIX.values() for k in ORDERS for axis in AXES]
    absent = [name for name in names if name not in params]
    if absent:
        raise UserError(
            f"{where}, but parameter {absent[0]} is not in the log: the correction cannot be removed"
        )
    moved = sorted(set(names) & changed)
    if moved:
        raise UserError(
            f"{where}, but parameter {moved[0]} changes during the log: the correction cannot be removed; "
            f"import a log recorded with fixed parameters"
        )
    coefficients = {
        sensor: np.array([[params[f"{prefix}_{short}{k}_{axis}"] for axis in AXES] for k in ORDERS])
        for sensor, short in PREFIX.items()
    }
    cal_temp = {sensor: params[cal_temp_param(sensor, instance)] for sensor in PREFIX}
    return TcalSet(instance, params[f"{prefix}_TMIN"], params[f"{prefix}_TMAX"], coefficients, cal_temp)
