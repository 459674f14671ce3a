"""Shared checks of the one-module IMU export (tests/export/test_imu_*.py): the ASan/UBSan harness
that streams records with resets through ``imu0_step``, the extreme-value burst appended to a
recording's inputs, and each channel's golden model reset at the same samples (as ``imu0_reset``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from codegen.golden_select import golden_for
from codegen.hostbuild import SANITIZER_FLAGS, build_harness, run_harness

NAME = "imu0"  # the module name the harness includes and calls
I32 = np.iinfo(np.int32)

HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "imu0.h"
/* records: raw[C], temp[S], command (1: imu0_reset before the sample); outputs C int32; stdout: flags, samples */
int main(int argc, char **argv)
{
    FILE *in = fopen(argv[1], "rb");
    FILE *out = fopen(argv[2], "wb");
    int32_t record[IMU0_CHANNELS + IMU0_SENSORS + 1u];
    int32_t y[IMU0_CHANNELS];
    /* heap copies: AddressSanitizer guards the bounds of the state and of the calibration */
    imu0_state_t *state = (imu0_state_t *)malloc(sizeof *state);
    imu0_calibration_t *cal = (imu0_calibration_t *)malloc(sizeof *cal);
    if (argc != 3 || in == NULL || out == NULL || state == NULL || cal == NULL) {
        return 2;
    }
    memcpy(cal, imu0_builtin(), sizeof *cal);
    imu0_init(state, cal);
    while (fread(record, sizeof record[0], IMU0_CHANNELS + IMU0_SENSORS + 1u, in) == IMU0_CHANNELS + IMU0_SENSORS + 1u) {
        if (record[IMU0_CHANNELS + IMU0_SENSORS] == 1) {
            imu0_reset(state);
        }
        imu0_step(state, record, record + IMU0_CHANNELS, y);
        fwrite(y, sizeof y[0], IMU0_CHANNELS, out);
    }
    fwrite(state->flags, sizeof state->flags[0], IMU0_CHANNELS, stdout);
    fwrite(&state->samples, sizeof state->samples, 1u, stdout);
    free(state);
    free(cal);
    fclose(in);
    return fclose(out) == 0 ? 0 : 7;
}
"""


def append_burst(
    raw: np.ndarray, temp: np.ndarray, rows: int, *, temp_lows: bool
) -> tuple[np.ndarray, np.ndarray]:
    """``rows`` random int32 samples after the inputs (seeded): the first 100 accelerations alternate
    between the int32 extremes, every third temperature is INT32_MAX and, with ``temp_lows``, every
    fifth from the second INT32_MIN."""
    rng = np.random.default_rng(5)
    burst_raw = rng.integers(-(2**31), 2**31, size=(rows, raw.shape[1])).astype(np.int32)
    burst_raw[:100:2], burst_raw[1:100:2] = I32.max, I32.min
    burst_temp = rng.integers(-(2**31), 2**31, size=(rows, temp.shape[1])).astype(np.int32)
    burst_temp[::3] = I32.max
    if temp_lows:
        burst_temp[1::5] = I32.min
    return np.concatenate([raw, burst_raw]), np.concatenate([temp, burst_temp])


def sanitized_run_with_resets(
    out_dir: Path, raw: np.ndarray, temp: np.ndarray, cuts: list[int], work: Path
) -> tuple[np.ndarray, np.ndarray]:
    """The exported module under ASan/UBSan (-O1) with ``imu0_reset`` before each cut sample: its
    outputs (int64, like ``raw``) and its final state words (each channel's flags, then samples)."""
    commands = np.zeros((len(raw), 1), dtype=np.int32)
    commands[cuts] = 1
    (work / "vectors.bin").write_bytes(np.concatenate([raw, temp, commands], axis=1).astype("<i4").tobytes())
    binary = build_harness(out_dir, NAME, HARNESS, work / "harness", flags=("-O1", *SANITIZER_FLAGS))
    state = np.frombuffer(run_harness(binary, work / "vectors.bin", work / "out.bin"), dtype="<u4")
    outputs = np.fromfile(work / "out.bin", dtype="<i4").reshape(raw.shape)
    return outputs.astype(np.int64), state


def golden_with_resets(
    imu: Any, raw: np.ndarray, temp: np.ndarray, cuts: list[int]
) -> tuple[np.ndarray, list[int]]:
    """Each channel's golden model (codegen.imu.ImuModel ``imu``), reset (not re-initialised) at
    every cut as ``imu0_reset``: outputs and final flags."""
    outputs = np.empty(raw.shape, dtype=np.int64)
    flags = []
    for k, channel in enumerate(imu.channels):
        golden = golden_for(channel.model.quantised)
        sensor = imu.sensors.index(channel.sensor)
        for a, b in zip([0, *cuts], [*cuts, len(raw)], strict=True):
            if a:
                golden.reset()
            outputs[a:b, k] = golden.run(raw[a:b, k].astype(np.int64), temp[a:b, sensor].astype(np.int64))
        flags.append(golden.flags)
    return outputs, flags


def accel_gyro_columns(seed: int, n: int = 1200) -> dict[str, np.ndarray]:
    """A 2 Hz two-channel run (accel0_z in mg, gyro0_x in deg/s, each its own curve in temperature over
    -10..50 degC), accel_mg a copy of accel0_z: what the export and verify tests of one API need."""
    rng = np.random.default_rng(seed)
    temp = np.linspace(-10.0, 50.0, n)
    u = (temp - 20.0) / 30.0
    columns = {"time_s": np.arange(n) / 2.0, "temp_c": temp}
    columns["accel0_z_mg"] = -1000.0 + 2.0 * u - u**2 + rng.normal(0, 0.05, n)
    columns["gyro0_x_dps"] = 0.3 * u + 0.1 * u**3 + rng.normal(0, 0.01, n)
    columns["accel_mg"] = columns["accel0_z_mg"]
    return columns
