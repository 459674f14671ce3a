"""DLSTM channels in the one-module IMU export (docs/imu-module.md, "DLSTM channels").

A three-channel recording at 10 Hz: accel0_x with a recursive DLSTM, accel0_y with a cubic and
gyro0_z with a temperature-input DLSTM (random weights in the trainer's layout, tests/testmodels.py).
The module must equal each channel's golden model (gcc and clang, strict warnings; ASan + UBSan
with resets, extremes and out-of-range temperatures), and each DLSTM channel must equal the
one-channel module of the same checkpoint exported alone, sample for sample.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from codegen.hostbuild import load_module
from codegen.imu import load_imu
from codegen.imu_record import KIND_STREAM
from codegen.imu_verify import host_run, step_inputs, verify_imu
from codegen.quantize import FLAG_INPUT_CLAMPED, FLAG_TEMP_OUT_OF_RANGE
from tests import testmodels as tm
from tests.imu_checks import NAME, append_burst, golden_with_resets, sanitized_run_with_resets
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording
from trainer.errors import run_cli

RATE_HZ = 10.0
N = 6000  # 10 minutes: one heating and one cooling ramp
FITS = (("dlstm", "accel0_x"), ("poly3", "accel0_y"), ("dlstm-temp", "gyro0_z"))  # the module's order


def imu_recording() -> Recording:
    rng = np.random.default_rng(11)
    temp = np.concatenate([np.linspace(-10, 50, N // 2), np.linspace(50, -10, N - N // 2)])
    u = (temp - 20.0) / 30.0
    columns = {"time_s": np.arange(N) / RATE_HZ, "temp_c": temp + rng.normal(0, 0.01, N)}
    columns["accel0_x_mg"] = 4.0 + 2.0 * u - u**2 + rng.normal(0, 0.05, N)
    columns["accel0_y_mg"] = -3.0 + 1.5 * u + 0.5 * u**3 + rng.normal(0, 0.05, N)
    columns["gyro0_z_dps"] = 0.1 + 0.05 * u + 0.02 * u**2 + rng.normal(0, 0.002, N)
    columns["accel_mg"] = columns["accel0_x_mg"]
    return Recording(columns, {"sample_rate_hz": f"{RATE_HZ:g}", "channel": "accel0_x"}, "imu-dlstm")


@pytest.fixture(scope="module")
def module(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("imu-dlstm")
    rec = imu_recording()
    write_recording(rec, root / "imu.npz")
    paths = {}
    for seed, (method, channel) in enumerate(FITS):
        column = next(c for c in rec.columns if c.startswith(f"{channel}_"))
        view = Recording(
            {"time_s": rec.time_s, "temp_c": rec.temp_c, "accel_mg": rec.columns[column]},
            {"sample_rate_hz": f"{RATE_HZ:g}"},
            channel,
        )
        checkpoint = tm.checkpoint_for(method, view, hidden=6, layers=2, seed=seed)
        unit = "dps" if channel.startswith("gyro") else "mg"
        checkpoint["train_stats"] = {**checkpoint["train_stats"], "channel": channel, "unit": unit}
        paths[channel] = root / f"{channel}.pt"
        tm.save_checkpoint(checkpoint, paths[channel])
    out = root / "c"
    assert codegen_main(["export", *map(str, paths.values()), "-o", str(out), "--name", NAME]) == 0
    return {"root": root, "rec": root / "imu.npz", "out": out, **paths}


def _models(module: dict[str, Path]) -> list[Path]:
    return [module[channel] for _, channel in FITS]


def test_module_holds_dlstm_channels_and_is_bit_exact(module: dict[str, Path]) -> None:
    imu = load_imu(_models(module))
    assert [c.kind for c in imu.channels] == [KIND_STREAM, 1, KIND_STREAM]
    rec = read_recording(module["rec"])
    for cc in ("gcc", "clang"):  # strict warnings are errors with both
        if shutil.which(cc) is None:
            continue
        result = verify_imu(_models(module), module["out"], rec, cc=cc)
        assert [(r.target, r.calibration) for r in result.runs] == [("host", "builtin")]
        assert result.runs[0].mismatches == [0, 0, 0] and result.runs[0].state_equal
    header = (module["out"] / f"{NAME}.h").read_text()
    assert "#define IMU0_SAMPLE_RATE_MILLIHZ 10000u" in header and "imu0_accel0_x_state_t accel0_x;" in header
    assert sorted(p.name for p in module["out"].iterdir()) == [
        "imu0.c", "imu0.h", "imu0.manifest.json", "tdc_kernels.h"
    ]  # fmt: skip


def test_dlstm_channels_equal_their_one_channel_modules(module: dict[str, Path], tmp_path: Path) -> None:
    """Independent of the golden model: each checkpoint exported alone, as before."""
    rec = read_recording(module["rec"])
    imu = load_imu(_models(module))
    raw, temp = step_inputs(imu, rec)
    out, _, _ = host_run(module["out"], NAME, raw, temp, None, None)
    for k, (method, channel) in enumerate(FITS):
        if not method.startswith("dlstm"):
            continue
        alone = tmp_path / channel
        assert codegen_main(["export", str(module[channel]), "-o", str(alone), "--name", "one"]) == 0
        one = load_module(alone, "one")
        sensor = imu.sensors.index(imu.channels[k].sensor)
        single = one.run(one.new_state(), raw[:, k].astype(np.int32), temp[:, sensor].astype(np.int32))
        np.testing.assert_array_equal(out[:, k], single)
        assert np.any(out[:, k] != raw[:, k])  # the network's estimate is removed


def test_under_asan_ubsan_with_resets_extremes_and_out_of_range(
    module: dict[str, Path], tmp_path: Path
) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    imu = load_imu(_models(module))
    raw, temp = step_inputs(imu, read_recording(module["rec"]).slice(0, 2000))
    raw, temp = append_burst(raw, temp, 400, temp_lows=False)
    cuts = [700, 2000, 2210]  # a reset mid-ramp, one before the burst, one inside it
    c_out, state = sanitized_run_with_resets(module["out"], raw, temp, cuts, tmp_path)
    g_out, g_flags = golden_with_resets(imu, raw, temp, cuts)
    np.testing.assert_array_equal(c_out, g_out)
    assert list(state[:-1]) == g_flags and state[-1] == len(raw)
    for k, (method, _) in enumerate(FITS):  # what each clamps: the accel input, the temperature
        assert g_flags[k] & FLAG_TEMP_OUT_OF_RANGE and g_flags[k] & FLAG_INPUT_CLAMPED, (method, g_flags[k])


def test_blob_refused_and_long_names_refused_in_one_line(
    module: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    models = list(map(str, _models(module)))
    for extra, fragment in (
        (["--blob"], "a DLSTM channel has no calibration-blob record"),
        (["--name", "a_twenty_char_name_x"], "choose a shorter --name"),
    ):
        code = run_cli(codegen_main, ["export", *models, "-o", str(tmp_path / "b"), *extra])
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and fragment in err, err
        assert not (tmp_path / "b").exists()


def test_dlstm_channel_on_cortex_m4(module: dict[str, Path], tmp_path: Path) -> None:
    if shutil.which("arm-none-eabi-gcc") is None or shutil.which("qemu-system-arm") is None:
        pytest.skip("Cortex-M toolchain unavailable")
    write_recording(read_recording(module["rec"]).slice(0, 1500), tmp_path / "part.npz")
    result = verify_imu(_models(module), module["out"], read_recording(tmp_path / "part.npz"), cortex_m4=True)
    assert [(r.target, sum(r.mismatches), r.state_equal) for r in result.runs] == [
        ("host", 0, True), ("cortex-m4", 0, True)
    ]  # fmt: skip
