"""PX4 ULog (``.ulg``) -> channels, with ``pyulog``.

Topics read, every instance (``multi_id``) of each (uORB message definitions in PX4's ``msg/``):

- ``sensor_accel``: ``x``, ``y``, ``z`` in m/s^2 (-> mg), ``temperature`` degC, ``device_id``;
- ``sensor_gyro``: ``x``, ``y``, ``z`` in rad/s (-> deg/s), ``temperature``, ``device_id``;
- ``sensor_baro``: ``pressure`` in Pa (PX4 before v1.13 logged hPa: a median below
  :data:`HPA_BELOW` is read as hPa and noted), ``temperature``, ``device_id``.

Time is ``timestamp_sample`` (when the sensor sampled) when the topic has it, else ``timestamp``,
both microseconds of the autopilot's clock. The instance number of a channel is the topic's
``multi_id``; the device id (what PX4's ``TC_*_ID`` parameters match) goes with it.

``sensor_combined`` (what older PX4 versions and the default logging profile write) holds the
IMU data without any sensor temperature, so it is not read as channels; a log whose IMU data is
only there says so, and what to log instead (:data:`COMBINED_ONLY`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

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

TOPICS = {"sensor_accel": "accel", "sensor_gyro": "gyro", "sensor_baro": "baro"}
SCALE = {"accel": MG_PER_MPS2, "gyro": DPS_PER_RADPS}
COMBINED = "sensor_combined"
COMBINED_ONLY = (
    "its IMU data is only in {topic} ({samples} samples), which carries no sensor temperature; a thermal "
    "calibration needs the per-sensor topics sensor_accel and sensor_gyro with their temperature: log "
    "with the thermal calibration profile selected in SDLOG_PROFILE (PX4 parameter) and record again"
)
HPA_BELOW = 2000.0  # a pressure median below this is hPa (sea level is 1013 hPa = 101325 Pa)


def read_ulog(path: str | Path) -> FlightLog:
    """Every instance of the accelerometer, gyroscope and barometer topics of a ULog file."""
    from pyulog import ULog

    source = str(path)
    reader_notices: list[str] = []
    ulog: Any = quiet_library_call(source, "ulog", lambda: ULog(source, [*TOPICS, COMBINED]), reader_notices)
    channels: list[LogChannel] = []
    notes: dict[str, str] = {}
    combined_samples = 0
    for dataset in ulog.data_list:
        if dataset.name == COMBINED:
            combined_samples += len(dataset.data["timestamp"])
        sensor = TOPICS.get(dataset.name)
        if sensor is None:
            continue
        try:
            channels.extend(
                _topic_channels(source, dataset.name, sensor, int(dataset.multi_id), dataset.data, notes)
            )
        except UserError as error:
            if not ulog.file_corruption:
                raise
            # what the damage made of the data, not a fault of the logging (a device id that "changes")
            raise UserError(
                f"{error} (the file is damaged: pyulog skipped what it could not read, and this is likely "
                "what the damage left; not a readable PX4 ULog log)"
            ) from None
    if ulog.file_corruption:
        notes["log_corruption"] = "pyulog detected file corruption; damaged messages were skipped"
        reader_notices.append(corruption_notice(source, channels))
    imu = any(channel.sensor != "baro" for channel in channels)
    missing = (
        COMBINED_ONLY.format(topic=COMBINED, samples=combined_samples) if combined_samples and not imu else ""
    )
    return FlightLog(source, "ulog", sorted_channels(channels), notes, reader_notices, missing=missing)


def corruption_notice(source: str, channels: list[LogChannel]) -> str:
    """What a damaged ULog may have lost, said on the terminal: pyulog skips what it cannot read, and
    a log damaged in the middle kept its first half only, with nothing said but a metadata line
    (pyulog cannot tell how much followed the damage: the samples read end where it stopped)."""
    read = [c.time_us for c in channels if c.time_us.size]
    kept = (
        f"the samples read span {(max(int(t[-1]) for t in read) - min(int(t[0]) for t in read)) / 1e6:.1f} s"
        if read
        else "no sample was read"
    )
    return (
        f"{source}: the file is damaged and pyulog skipped what it could not read, which can be everything "
        f"after the damage: {kept}; compare with the log's duration before using it"
    )


def _topic_channels(
    source: str, topic: str, sensor: str, instance: int, data: dict[str, np.ndarray], notes: dict[str, str]
) -> list[LogChannel]:
    where = f"{source}: topic {topic} instance {instance}"
    fields = ("pressure",) if sensor == "baro" else AXES
    missing = [name for name in ("timestamp", "temperature", *fields) if name not in data]
    if missing:
        raise UserError(f"{where}: field {missing[0]!r} is missing (not a PX4 {topic} message?)")
    time_us = np.asarray(data.get("timestamp_sample", data["timestamp"]), dtype=np.int64)
    if len(time_us) == 0:
        return []
    temp_c = np.asarray(data["temperature"], dtype=np.float64)
    device_id = _device_id(where, data.get("device_id"))
    if sensor == "baro":
        pressure = np.asarray(data["pressure"], dtype=np.float64)
        finite = pressure[np.isfinite(pressure)]
        if finite.size and np.median(finite) < HPA_BELOW:
            pressure = pressure * 100.0
            notes[f"units_baro{instance}"] = "pressure logged in hPa (PX4 before v1.13), converted to Pa"
        return [LogChannel(sensor, instance, None, time_us, pressure, temp_c, device_id)]
    scale = SCALE[sensor]
    return [
        LogChannel(
            sensor,
            instance,
            axis,
            time_us,
            np.asarray(data[axis], dtype=np.float64) * scale,
            temp_c,
            device_id,
        )
        for axis in AXES
    ]


def _device_id(where: str, values: np.ndarray | None) -> int | None:
    """The instance's one device id; a change within the log means two sensors share an instance."""
    if values is None or len(values) == 0:
        return None
    ids = np.unique(values)
    if ids.size > 1:
        raise UserError(f"{where}: device id changes within the log ({', '.join(map(str, ids[:4]))})")
    return int(ids[0])
