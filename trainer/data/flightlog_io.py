"""Read a flight log of either kind: the magic bytes pick the reader."""

from __future__ import annotations

from pathlib import Path

from trainer.data.dataflash_reader import read_dataflash
from trainer.data.flightlog import A_KIND, FlightLog, log_kind
from trainer.data.ulog_reader import read_ulog
from trainer.errors import UserError

READ = {"ulog": "no sensor_accel, sensor_gyro or sensor_baro topic", "dataflash": "no IMU or BARO message"}


def read_flight_log(path: str | Path) -> FlightLog:
    """Read a ULog or DataFlash log (decided by magic bytes) into channels."""
    kind = log_kind(path)
    if kind is None:
        raise UserError(f"{path}: not a PX4 ULog or ArduPilot DataFlash log (magic bytes do not match)")
    log = read_ulog(path) if kind == "ulog" else read_dataflash(path)
    if not log.channels:
        missing = log.missing or f"it has {READ[kind]}"
        raise UserError(
            f"{path}: {A_KIND[kind]} log without accelerometer, gyroscope or barometer channels: {missing}"
        )
    return log
