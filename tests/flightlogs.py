"""Small flight logs written by the tests (no network, no recorded fixtures).

ULog: pyulog reads but cannot build a log from scratch through a public API, so
:func:`write_ulog` follows the published format (PX4 docs, "ULog File Format"): a 16-byte header
(magic ``ULog`` 0x01 0x12 0x35, version 1, start time uint64 us), the flag-bits message ``B``,
one format message ``F`` per topic (``name:type field;...``), then for each topic instance an
add-logged-message ``A`` (multi_id, msg_id, name) and its data messages ``D`` (msg_id, packed
fields, little-endian). Every message is ``uint16 size, uint8 type, payload``.

DataFlash: written with pymavlink's own ``DFFormat``/``DFMessage`` (``get_msgbuf``): ``FMT``
messages first, then ``PARM``, ``IMU`` and ``BARO`` with ArduPilot's field layouts.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ULOG_MAGIC = b"ULog\x01\x12\x35"
ULOG_TYPES = {"uint64_t": "Q", "uint32_t": "I", "float": "f", "uint8_t": "B", "int32_t": "i"}
ULOG_ARRAY = re.compile(r"(\w+)\[([0-9]+)\]")  # float[3]: a fixed-size array field

ACCEL_FIELDS = [
    ("uint64_t", "timestamp"),
    ("uint64_t", "timestamp_sample"),
    ("uint32_t", "device_id"),
    ("float", "x"),
    ("float", "y"),
    ("float", "z"),
    ("float", "temperature"),
]
# sensor_combined as older PX4 versions and the default logging profile write it: no temperature.
COMBINED_FIELDS = [
    ("uint64_t", "timestamp"),
    ("float[3]", "gyro_rad"),
    ("uint32_t", "gyro_integral_dt"),
    ("int32_t", "accelerometer_timestamp_relative"),
    ("float[3]", "accelerometer_m_s2"),
    ("uint32_t", "accelerometer_integral_dt"),
]
BARO_FIELDS = [
    ("uint64_t", "timestamp"),
    ("uint64_t", "timestamp_sample"),
    ("uint32_t", "device_id"),
    ("float", "pressure"),
    ("float", "temperature"),
]


@dataclass
class Topic:
    """One instance of a topic: ``rows`` are tuples in the order of ``fields``."""

    name: str
    multi_id: int
    fields: list[tuple[str, str]]
    rows: list[tuple[float | int | tuple[float, ...], ...]]  # a tuple for an array field


def _message(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def write_ulog(path: Path, topics: list[Topic], start_us: int = 1_000_000) -> Path:
    """A ULog file of ``topics`` (data messages interleaved by timestamp, as a logger writes them)."""
    out = bytearray(ULOG_MAGIC + struct.pack("<BQ", 1, start_us))
    out += _message(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
    formats: dict[str, list[tuple[str, str]]] = {}
    for topic in topics:
        formats.setdefault(topic.name, topic.fields)
    for name, fields in formats.items():
        out += _message(b"F", (name + ":" + "".join(f"{t} {f};" for t, f in fields)).encode())
    items: list[tuple[int, int, bytes]] = []
    for msg_id, topic in enumerate(topics):
        out += _message(b"A", struct.pack("<BH", topic.multi_id, msg_id) + topic.name.encode())
        codes = "<" + "".join(_struct_code(t) for t, _ in topic.fields)
        for row in topic.rows:
            flat = [item for value in row for item in (value if isinstance(value, tuple) else (value,))]
            items.append((int(row[0]), msg_id, struct.pack("<H", msg_id) + struct.pack(codes, *flat)))
    for _, _, payload in sorted(items, key=lambda item: (item[0], item[1])):
        out += _message(b"D", payload)
    path.write_bytes(bytes(out))
    return path


def _struct_code(ulog_type: str) -> str:
    """``float`` -> ``f``; ``float[3]`` -> ``3f`` (an array row value is a tuple)."""
    array = ULOG_ARRAY.fullmatch(ulog_type)
    return f"{array.group(2)}{ULOG_TYPES[array.group(1)]}" if array else ULOG_TYPES[ulog_type]


def combined_topic(time_us: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> Topic:
    """sensor_combined rows (rad/s, m/s^2), no temperature field."""
    rows: list[tuple[float | int | tuple[float, ...], ...]] = [
        (int(t), tuple(map(float, g)), 4000, 0, tuple(map(float, a)), 4000)
        for t, g, a in zip(time_us, gyro, accel, strict=True)
    ]
    return Topic("sensor_combined", 0, COMBINED_FIELDS, rows)


def imu_topic(
    name: str, multi_id: int, device_id: int, time_us: np.ndarray, xyz: np.ndarray, temp_c: np.ndarray
) -> Topic:
    """sensor_accel / sensor_gyro rows: timestamp a little after timestamp_sample, as PX4 logs them."""
    rows = [
        (int(t) + 150, int(t), device_id, *map(float, v), float(c))
        for t, v, c in zip(time_us, xyz, temp_c, strict=True)
    ]
    return Topic(name, multi_id, ACCEL_FIELDS, rows)


def baro_topic(
    multi_id: int, device_id: int, time_us: np.ndarray, pa: np.ndarray, temp_c: np.ndarray
) -> Topic:
    rows = [
        (int(t) + 90, int(t), device_id, float(p), float(c))
        for t, p, c in zip(time_us, pa, temp_c, strict=True)
    ]
    return Topic("sensor_baro", multi_id, BARO_FIELDS, rows)


# --------------------------------------------------------------------------- DataFlash

IMU_FORMAT = ("QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz")
BARO_FORMAT = ("QBffcfIffB", "TimeUS,I,Alt,Press,Temp,CRt,SMS,Offset,GndTemp,Health")
PARM_FORMAT = ("QNf", "TimeUS,Name,Value")


class DataFlashWriter:
    """Build a DataFlash log message by message with pymavlink's DFFormat/DFMessage."""

    def __init__(self) -> None:
        from pymavlink.DFReader import DFFormat

        self._format_cls = DFFormat
        self.fmt = DFFormat(128, "FMT", 89, "BBnNZ", "Type,Length,Name,Format,Columns")
        self.buffer = bytearray(
            self._pack(self.fmt, [128, 89, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"])
        )
        self.formats: dict[str, object] = {}
        for type_id, (name, (fmt, columns)) in enumerate(
            {"PARM": PARM_FORMAT, "IMU": IMU_FORMAT, "BARO": BARO_FORMAT}.items(), start=129
        ):
            length = 3 + struct.calcsize(self._format_cls(type_id, name, 0, fmt, columns).msg_struct)
            self.formats[name] = self._format_cls(type_id, name, length, fmt, columns)
            self.buffer += self._pack(self.fmt, [type_id, length, name, fmt, columns])

    @staticmethod
    def _pack(fmt: object, values: list[object]) -> bytes:
        from pymavlink.DFReader import DFMessage

        packed = DFMessage(fmt, values, False, None).get_msgbuf()
        assert packed is not None, f"values do not fit the format: {values}"
        return bytes(packed)

    def add(self, name: str, values: list[object]) -> None:
        self.buffer += self._pack(self.formats[name], values)

    def parm(self, time_us: int, name: str, value: float) -> None:
        self.add("PARM", [time_us, name, value])

    def imu(self, time_us: int, instance: int, gyr: np.ndarray, acc: np.ndarray, temp_c: float) -> None:
        self.add(
            "IMU",
            [time_us, instance, *map(float, gyr), *map(float, acc), 0, 0, float(temp_c), 1, 1, 1000, 1000],
        )

    def baro(self, time_us: int, instance: int, pressure_pa: float, temp_c: float) -> None:
        self.add(
            "BARO",
            [time_us, instance, 12.5, float(pressure_pa), float(temp_c), 0.0, time_us // 1000, 0.0, 20.0, 1],
        )

    def write(self, path: Path) -> Path:
        path.write_bytes(bytes(self.buffer))
        return path
