"""ArduPilot DataFlash (``.bin``) -> channels, with ``pymavlink``'s ``DFReader``.

Messages read (ArduPilot's ``LogStructure.h`` of AP_InertialSensor and AP_Baro):

- ``IMU``: ``TimeUS``, instance ``I``, ``AccX..Z`` m/s^2 (-> mg), ``GyrX..Z`` rad/s (-> deg/s),
  ``T`` degC. Older logs write ``IMU``, ``IMU2``, ``IMU3`` without ``I``: the name is the instance.
- ``BARO``: ``TimeUS``, ``I``, ``Press`` Pa, ``Temp`` degC.
- ``PARM``: the device ids ``INS_ACC_ID``, ``INS_ACC2_ID``, ..., ``INS_GYR_ID``, ..., ``BARO1_DEVID``,
  ... and ``AHRS_ORIENTATION``: ``IMU`` values are in the vehicle frame (after the board rotation),
  while ``INS_TCALn_*`` corrections apply in the sensor frame, so a non-zero orientation is noted.

An IMU whose ``INS_TCALn_ENABLE`` is 1 in the log was corrected before logging: the correction is
added back from the log's own parameters (:mod:`trainer.data.ardupilot_tcal`), so the channels
hold the raw drift that a calibration is fitted to.
"""

from __future__ import annotations

import re
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from trainer.data.ardupilot_tcal import logged_tcal
from trainer.data.flightlog import (
    AXES,
    DPS_PER_RADPS,
    MG_PER_MPS2,
    FlightLog,
    LogChannel,
    quiet_library_call,
    sorted_channels,
)
from trainer.errors import UserError

# The recording's metadata key of a non-zero AHRS_ORIENTATION: "<rotation> (IMU axes are vehicle axes, ...)".
ORIENTATION_KEY = "ahrs_orientation"


def board_rotation(meta: dict[str, str]) -> int | None:
    """The ArduPilot board rotation a recording's axes carry (``AHRS_ORIENTATION``; None: not noted,
    the sensor's own axes)."""
    words = meta.get(ORIENTATION_KEY, "").split()
    return int(words[0]) if words and words[0].isdigit() else None


IMU_NAME = re.compile(r"IMU([23]?)")
DEVICE_ID_PARAM = re.compile(r"INS_(ACC|GYR)([23]?)_ID|BARO([1-3])_DEVID")


def read_dataflash(path: str | Path) -> FlightLog:
    """Every IMU and barometer instance of a DataFlash log, with their temperatures."""
    source = str(path)
    rows: dict[tuple[str, int], list[tuple[float, ...]]] = defaultdict(list)
    params: dict[str, float] = {}
    changed: set[str] = set()  # parameters set to another value during the log

    def collect() -> None:
        from pymavlink.DFReader import DFReader_binary

        reader: Any = DFReader_binary(source, zero_time_base=False)
        wanted = ["IMU", "IMU2", "IMU3", "BARO", "PARM"]
        while (msg := reader.recv_match(type=wanted)) is not None:
            kind = msg.get_type()
            if kind == "PARM":
                name, value = str(msg.Name), float(msg.Value)
                if params.get(name, value) != value:
                    changed.add(name)
                params[name] = value
            elif kind == "BARO":
                rows["baro", int(getattr(msg, "I", 0))].append((msg.TimeUS, msg.Press, msg.Temp))
            else:
                match = IMU_NAME.fullmatch(kind)
                instance = int(getattr(msg, "I", int(match.group(1) or 1) - 1 if match else 0))
                rows["imu", instance].append(
                    (msg.TimeUS, msg.AccX, msg.AccY, msg.AccZ, msg.GyrX, msg.GyrY, msg.GyrZ, msg.T)
                )

    notices: list[str] = []  # printed at import: the reader's summarised warnings, corrections undone
    quiet_library_call(source, "dataflash", collect, notices)
    ids = _device_ids(params)
    orientation = int(params.get("AHRS_ORIENTATION", 0))
    channels: list[LogChannel] = []
    notes: dict[str, str] = {}
    for (kind, instance), samples in rows.items():
        table = np.array(samples, dtype=np.float64)
        if not np.all((table[:, 0] >= 0) & (table[:, 0] < 2.0**63)):  # NaN fails too
            raise UserError(
                f"{source}: {kind} instance {instance}: a TimeUS that is not a time in us (a damaged log)"
            )
        time_us = table[:, 0].astype(np.int64)
        if kind == "baro":
            channels.append(
                LogChannel(
                    "baro", instance, None, time_us, table[:, 1], table[:, 2], ids.get(("baro", instance))
                )
            )
            continue
        temp_c = table[:, 7]
        accel_mps2, gyro_rads = table[:, 1:4], table[:, 4:7]
        tcal = logged_tcal(params, changed, instance, orientation, source)
        if tcal is not None:
            accel_mps2 = accel_mps2 + tcal.correction("accel", temp_c)
            gyro_rads = gyro_rads + tcal.correction("gyro", temp_c)
            notices.append(f"{source}: {tcal.describe()}")
            notes[f"tcal_removed_imu{instance}"] = (
                "the logged INS_TCAL correction was added back (raw reading)"
            )
        for k, axis in enumerate(AXES):
            accel = accel_mps2[:, k] * MG_PER_MPS2
            gyro = gyro_rads[:, k] * DPS_PER_RADPS
            channels.append(
                LogChannel("accel", instance, axis, time_us, accel, temp_c, ids.get(("accel", instance)))
            )
            channels.append(
                LogChannel("gyro", instance, axis, time_us, gyro, temp_c, ids.get(("gyro", instance)))
            )
    if orientation:
        notes[ORIENTATION_KEY] = f"{orientation} (IMU axes are vehicle axes, not sensor axes)"
        notices.append(
            f"{source}: AHRS_ORIENTATION={orientation}: the IMU axes logged are the vehicle's, not the sensor's; "
            "INS_TCAL applies in the sensor frame, so codegen export --format ardupilot-parm refuses models of "
            "these channels (the C module and PX4 parameters are unaffected)"
        )
    return FlightLog(source, "dataflash", sorted_channels(channels), notes, notices)


def _device_ids(params: dict[str, float]) -> dict[tuple[str, int], int]:
    """(sensor, instance) -> device id from the PARM messages (0 means no sensor)."""
    ids: dict[tuple[str, int], int] = {}
    for name, value in params.items():
        match = DEVICE_ID_PARAM.fullmatch(name)
        if match is None or int(value) == 0:
            continue
        if match.group(3):
            ids["baro", int(match.group(3)) - 1] = int(value)
        else:
            sensor = "accel" if match.group(1) == "ACC" else "gyro"
            ids[sensor, int(match.group(2) or 1) - 1] = int(value)
    return ids
