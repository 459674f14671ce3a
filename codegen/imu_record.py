"""A channel's record of the IMU module (``NAME_channel_t``) and the channel kinds (``NAME_KIND_``,
the calibration blob's codes): what a C family's unit gives :mod:`codegen.imu` (its ``ImuForm``), and
a family's channels in a module (``ImuPart``), what its ``ImuForm`` hooks render from.

A module of its own, imported by the units and by codegen/imu.py, so that no unit imports the IMU
module (which reaches the units through the family registry only).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

KIND_CUBIC, KIND_PLA, KIND_PHYSICS, KIND_STREAM = 1, 2, 3, 4  # KIND_STREAM: built-in tables only


@dataclass(frozen=True)
class ChannelTables:
    """One channel's numbers exactly as ``NAME_channel_t`` holds them."""

    kind: int
    sensor: int
    frac: int
    u_shift: int
    clip_lo: int
    clip_hi: int
    t_ref: int
    coefficients: tuple[int, ...]  # cubic d0..d3 (zeros for pla)
    splits: tuple[int, ...]
    slopes: tuple[int, ...]
    intercepts: tuple[int, ...]


@dataclass(frozen=True)
class ImuPart:
    """One family's channels in an IMU module: what its ``ImuForm`` hooks (context, manifest) see."""

    module: str  # the IMU module's C name
    channels: tuple[Any, ...]  # codegen.imu.ImuChannel, in slot order
    indices: tuple[int, ...]  # each one's channel index in the module
