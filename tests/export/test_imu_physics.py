"""Physics channels in the one-module IMU export (docs/imu-module.md).

A three-channel recording (cooling, heating, cooling at 1 Hz) whose accel0_x carries thermal lag,
a temperature-rate term and a heating/cooling branch offset (the simulator's own drift formula),
accel0_y a cubic and gyro0_z a cubic in deg/s. accel0_x is fitted with ``--method physics`` (forced
structure), accel0_y with poly3, gyro0_z with pla; the IMU module must equal each channel's golden
model (gcc and clang, strict warnings, ASan/UBSan with resets and extremes), and its physics
channel must equal the one-channel physics module of the same checkpoint sample for sample.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from codegen import cortex_m as cm
from codegen.cli import main as codegen_main
from codegen.families.physics.quantise import QPhysics
from codegen.hostbuild import (
    FIRMWARE_WARNINGS,
    STRICT_FLAGS,
    load_module,
)
from codegen.imu import imu_golden, load_imu
from codegen.imu_record import KIND_PHYSICS
from codegen.imu_verify import host_run, step_inputs, verify_imu
from tests import testmodels as tm
from tests.imu_checks import NAME, append_burst, golden_with_resets, sanitized_run_with_resets
from trainer.checkpoint import load_checkpoint
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording
from trainer.errors import UserError, run_cli
from trainer.physics.effects import EffectConfig, drift

RATE_HZ = 1.0
# (duration s, from degC, to degC): cooling, heating, cooling with holds, 2 degC/min
SEGMENTS = ((300, 60.0, 60.0), (2100, 60.0, -10.0), (300, -10.0, -10.0), (2100, -10.0, 60.0),
            (300, 60.0, 60.0), (2100, 60.0, -10.0))  # fmt: skip
PHYSICS = (
    EffectConfig(
        "bias_poly", {"c0_mg": 0.4, "c1_mg_per_c": 0.15, "c2_mg_per_c2": 1e-3, "c3_mg_per_c3": -5e-6}
    ),
    EffectConfig("thermal_lag", {"tau_s": 120.0}),
    EffectConfig("temp_rate", {"k_mg_per_c_per_min": 0.3, "tau_s": 60.0}),
    EffectConfig("hysteresis_offset", {"amp_mg": 0.8, "width_c": 6.0}),
)
CHANNELS = ("accel0_x", "accel0_y", "gyro0_z")  # the module's order


def imu_recording(seed: int = 7) -> Recording:
    rng = np.random.default_rng(seed)
    temp = np.concatenate([np.linspace(a, b, int(d * RATE_HZ), endpoint=False) for d, a, b in SEGMENTS])
    n = temp.size
    time_s = np.arange(n) / RATE_HZ
    u = (temp - 25.0) / 35.0
    columns = {
        "time_s": time_s,
        "temp_c": temp + rng.normal(0, 0.01, n),
        "accel0_x_mg": 5.0 + drift(PHYSICS, time_s, temp).total + rng.normal(0, 0.05, n),
        "accel0_y_mg": -3.0 + 2.0 * u - 1.5 * u**2 + 0.8 * u**3 + rng.normal(0, 0.05, n),
        "gyro0_z_dps": 0.1 + 0.05 * u + 0.02 * u**2 + rng.normal(0, 0.002, n),
    }
    columns["accel_mg"] = columns["accel0_x_mg"]
    return Recording(columns, {"sample_rate_hz": f"{RATE_HZ:g}", "channel": "accel0_x"}, "imu-physics")


@pytest.fixture(scope="module")
def fitted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("imu-physics")
    write_recording(imu_recording(), root / "imu.npz")
    fits = (
        [
            "--method",
            "physics",
            "--effects",
            "thermal_lag,hysteresis_offset,temp_rate",
            "--channels",
            "accel0_x",
        ],
        ["--method", "poly3", "--channels", "accel0_y"],
        ["--method", "pla", "--intervals", "4", "--channels", "gyro0_z"],
    )
    for argv, channel in zip(fits, CHANNELS, strict=True):
        assert trainer_main(["fit", *argv, str(root / "imu.npz"), "-o", str(root / channel)]) == 0
    models = [root / c / f"{c}.pt" for c in CHANNELS]
    out = root / "c"
    assert codegen_main(["export", *map(str, models), "-o", str(out), "--name", NAME]) == 0
    return {"root": root, "rec": root / "imu.npz", "out": out, **{c: root / c / f"{c}.pt" for c in CHANNELS}}


def _models(fitted: dict[str, Path]) -> list[Path]:
    return [fitted[c] for c in CHANNELS]


def test_module_holds_a_physics_channel_and_is_bit_exact(fitted: dict[str, Path]) -> None:
    imu = load_imu(_models(fitted))
    assert [c.kind for c in imu.channels] == [KIND_PHYSICS, 1, 2]
    q = imu.channels[0].model.quantised
    assert isinstance(q, QPhysics)  # the forced terms are exported
    assert {t.identifier for t in q.terms} == {"thermal_lag", "hysteresis_offset", "temp_rate"}
    rec = read_recording(fitted["rec"])
    for cc in ("gcc", "clang"):  # strict warnings are errors with both
        if shutil.which(cc) is None:
            continue
        result = verify_imu(_models(fitted), fitted["out"], rec, cc=cc)
        assert [(r.target, r.calibration) for r in result.runs] == [("host", "builtin")]
        assert result.runs[0].mismatches == [0, 0, 0] and result.runs[0].state_equal
    header = (fitted["out"] / f"{NAME}.h").read_text()
    assert "accel0_x [mg], physics" in header and "#define IMU0_SAMPLE_RATE_MILLIHZ 1000u" in header
    assert (fitted["out"] / "tdc_physics_kernels.h").is_file()


def test_a_channel_that_carries_an_undetermined_parameter_is_named_with_its_warning(
    fitted: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The IMU export says, per channel, what that channel's own module would write in its header:
    the parameters its training run does not determine (none for the fixture's fit)."""
    raw = load_checkpoint(fitted["accel0_x"])
    report = raw["payload"]["report"]
    flagged = {**raw, "payload": {**raw["payload"], "report": {**report, "implausible": ["temp_rate.tau_s"]}}}
    path = tmp_path / "accel0_x.pt"
    tm.save_checkpoint(flagged, path)
    for first, warned in (
        (fitted["accel0_x"], bool(report["at_bound"] or report["implausible"])),
        (path, True),
    ):
        capsys.readouterr()
        argv = [
            "export",
            str(first),
            str(fitted["accel0_y"]),
            str(fitted["gyro0_z"]),
            "-o",
            str(tmp_path / "c"),
        ]
        assert codegen_main([*argv, "--name", NAME]) == 0
        out = capsys.readouterr().out
        assert (
            "accel0_x: WARNING: the model carries what its training run does not determine" in out
        ) == warned
        assert ("temp_rate.tau_s is outside the catalogue's plausible range" in out) == (first == path)
        shutil.rmtree(tmp_path / "c")


def test_physics_channel_equals_the_one_channel_physics_module(
    fitted: dict[str, Path], tmp_path: Path
) -> None:
    """Independent of the golden model: the existing one-channel physics export of the same file."""
    assert (
        codegen_main(["export", str(fitted["accel0_x"]), "-o", str(tmp_path / "one"), "--name", "one"]) == 0
    )
    one = load_module(tmp_path / "one", "one")
    rec = read_recording(fitted["rec"])
    imu = load_imu(_models(fitted))
    raw, temp = step_inputs(imu, rec)
    single = one.run(one.new_state(), raw[:, 0].astype(np.int32), temp[:, 0].astype(np.int32))
    out, _, _ = host_run(fitted["out"], NAME, raw, temp, None, None)
    np.testing.assert_array_equal(out[:, 0], single)
    assert np.ptp(out[:, 0] - raw[:, 0]) > 16000 * 5  # the drift removed spans several mg


def test_under_asan_ubsan_with_resets_extremes_and_out_of_range(
    fitted: dict[str, Path], tmp_path: Path
) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    rec = read_recording(fitted["rec"])
    imu = load_imu(_models(fitted))
    raw, temp = step_inputs(imu, rec.slice(0, 3000))
    raw, temp = append_burst(raw, temp, 600, temp_lows=True)
    cuts = [1000, 3000, 3300]  # a reset mid-ramp, one before the burst, one inside it
    c_out, state = sanitized_run_with_resets(fitted["out"], raw, temp, cuts, tmp_path)
    g_out, g_flags = golden_with_resets(imu, raw, temp, cuts)
    np.testing.assert_array_equal(c_out, g_out)
    assert list(state[:-1]) == g_flags and state[-1] == len(raw)
    assert all(f & 1 and f & 4 for f in g_flags)  # out of range and saturated on every channel


@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_strict_and_firmware_warnings(fitted: dict[str, Path], compiler: str, tmp_path: Path) -> None:
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} is not installed")
    for opt in ("-O0", "-O2", "-Os"):
        result = subprocess.run(
            [compiler, *STRICT_FLAGS, *FIRMWARE_WARNINGS, opt, "-c", str(fitted["out"] / f"{NAME}.c"),
             "-o", str(tmp_path / "m.o")],
            capture_output=True, text=True,
        )  # fmt: skip
        assert result.returncode == 0 and not result.stderr, f"{compiler} {opt}: {result.stderr}"
    text = (fitted["out"] / f"{NAME}.c").read_text()
    assert not any(word in text for word in ("malloc", "<math.h>", "<stdio.h>", "float", "double"))


def test_refusals_are_one_line(
    fitted: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    models = list(map(str, _models(fitted)))
    for extra in (["--blob"], ["--format", "calibration-blob"]):
        code = run_cli(codegen_main, ["export", *models, "-o", str(tmp_path / "b"), *extra])
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and "physics channel" in err, err
        assert not (tmp_path / "b").exists()
    # a recording at another rate than the filters'
    fast = imu_recording().slice(0, 200)
    fast.meta["sample_rate_hz"] = "2"
    fast.columns["time_s"] = fast.columns["time_s"] / 2.0
    write_recording(fast, tmp_path / "fast.npz")
    with pytest.raises(UserError, match=r"2 Hz, the physics channels' filters are for 1 Hz") as refused:
        verify_imu(_models(fitted), fitted["out"], read_recording(tmp_path / "fast.npz"))
    assert "\n" not in str(refused.value)


def test_rate_option_rebuilds_the_physics_filters(fitted: dict[str, Path], tmp_path: Path) -> None:
    models = list(map(str, _models(fitted)))
    out = tmp_path / "fast"
    assert codegen_main(["export", *models, "-o", str(out), "--name", NAME, "--rate", "4"]) == 0
    assert "#define IMU0_SAMPLE_RATE_MILLIHZ 4000u" in (out / f"{NAME}.h").read_text()
    imu = load_imu(_models(fitted), rate_millihz=4000)
    rec = imu_recording().slice(0, 1500)
    rec.meta["sample_rate_hz"] = "4"
    rec.columns["time_s"] = rec.columns["time_s"] / 4.0
    write_recording(rec, tmp_path / "fast.npz")
    result = verify_imu(_models(fitted), out, read_recording(tmp_path / "fast.npz"))
    assert result.runs[0].mismatches == [0, 0, 0] and result.runs[0].state_equal
    raw, temp = step_inputs(imu, read_recording(tmp_path / "fast.npz"))
    g_out, _, _ = imu_golden(imu, raw, temp)
    one_hz, _, _ = imu_golden(load_imu(_models(fitted)), raw, temp)
    assert np.any(g_out[:, 0] != one_hz[:, 0]) and np.array_equal(g_out[:, 1:], one_hz[:, 1:])


# What GCC requires any freestanding environment to provide (its manual, "C Language Dialect
# Options": memcpy, memmove, memset and memcmp): the only symbols the generated C may pull in.
FREESTANDING = {"memcpy", "memmove", "memset", "memcmp"}


def test_the_module_object_pulls_in_no_library_routine(fitted: dict[str, Path], tmp_path: Path) -> None:
    """The physics channel's final rounding shifts by a per-channel amount read from the tables; as
    an exact division by 2^(32 + s) it made gcc call __aeabi_ldivmod (a libgcc 64-bit division) on
    every step of the Cortex-M4 object, which a -nostdlib build cannot link."""
    if shutil.which("arm-none-eabi-gcc") is None or shutil.which("arm-none-eabi-nm") is None:
        pytest.skip("Cortex-M toolchain unavailable")
    out = tmp_path / "build"
    subprocess.run(
        ["make", "--no-print-directory", "-C", str(cm.FIRMWARE_DIR), f"MODULE_DIR={fitted['out']}",
         f"NAME={NAME}", f"OUT={out}", "module"],
        capture_output=True, check=True,
    )  # fmt: skip
    listed = subprocess.run(
        ["arm-none-eabi-nm", "-u", str(out / f"{NAME}.o")], capture_output=True, text=True, check=True
    ).stdout
    undefined = {line.split()[-1] for line in listed.splitlines() if line.strip()}
    assert undefined <= FREESTANDING, undefined


def test_physics_channel_on_cortex_m4(fitted: dict[str, Path], tmp_path: Path) -> None:
    if shutil.which("arm-none-eabi-gcc") is None or shutil.which("qemu-system-arm") is None:
        pytest.skip("Cortex-M toolchain unavailable")
    write_recording(read_recording(fitted["rec"]).slice(0, 2500), tmp_path / "part.npz")
    result = verify_imu(_models(fitted), fitted["out"], read_recording(tmp_path / "part.npz"), cortex_m4=True)
    assert [(r.target, sum(r.mismatches), r.state_equal) for r in result.runs] == [
        ("host", 0, True), ("cortex-m4", 0, True)
    ]  # fmt: skip
