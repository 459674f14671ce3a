"""The "input clamped" flag is set wherever the generated C clamps the temperature, in the golden model
too, for every module family (poly3, pla, physics, dlstm, imu).

Where each family clamps (docs/codegen.md): the cubic and the physics model clip T to the fitted
range; PLA and the temperature-input DLSTM clamp it to the front end's -100 .. 200 degC. A stream
inside those bounds must leave the bit clear; one beyond them must set it, in the C and in the
golden model, with bit-exact outputs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from codegen.export import export
from codegen.golden_select import golden_for
from codegen.hostbuild import load_module
from codegen.imu import imu_golden, load_imu
from codegen.imu_verify import host_run
from codegen.quantize import FLAG_INPUT_CLAMPED, FLAG_TEMP_OUT_OF_RANGE, TEMP_LIMITS_MDEGC
from tests import testmodels as tm
from trainer.data.recording import Recording

RATE_HZ = 10.0
TRAIN_C = (-10.0, 50.0)  # the fitted (valid) range


def _training() -> Recording:
    rng = np.random.default_rng(5)
    n = int(600 * RATE_HZ)
    temp = np.linspace(*TRAIN_C, n)
    u = (temp - 20.0) / 30.0
    accel = 2.0 * u - 1.0 * u**2 + 0.5 * u**3 + rng.normal(0, 0.05, n)
    return Recording(
        {"time_s": np.arange(n) / RATE_HZ, "temp_c": temp, "accel_mg": accel},
        {"sample_rate_hz": f"{RATE_HZ:g}"},
        "clamp-train",
    )


def _stream(lo_c: float, hi_c: float, n: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    """int32 accel (1/16 ug) and temperature (mdegC) sweeping lo_c .. hi_c and back."""
    half = n // 2
    temp_c = np.concatenate((np.linspace(lo_c, hi_c, half), np.linspace(hi_c, lo_c, n - half)))
    accel = np.round(16000 * 0.3 * np.sin(np.arange(n) / 50.0)).astype(np.int32)
    return accel, np.round(temp_c * 1000).astype(np.int32)


def _beyond(method: str) -> tuple[float, float]:
    """Temperatures just beyond where the family clamps (independent of the code: the docs' bounds)."""
    if method in ("poly3", "physics"):  # the fitted range
        return TRAIN_C[0] - 20.0, TRAIN_C[1] + 20.0
    lo, hi = (v / 1000 for v in TEMP_LIMITS_MDEGC)  # the front end's range
    return lo - 20.0, hi + 20.0


@pytest.fixture(scope="module")
def rec() -> Recording:
    return _training()


@pytest.mark.parametrize("method", ["poly3", "pla", "physics", "dlstm-temp"])
def test_clamping_the_temperature_sets_the_flag_bit_exactly(
    method: str, rec: Recording, tmp_path: Path
) -> None:
    path = tmp_path / f"{method}.pt"
    tm.save_checkpoint(tm.checkpoint_for(method, rec, hidden=4, layers=1), path)
    model, _ = export(path, tmp_path / "out", name="clamp")
    host = load_module(tmp_path / "out", "clamp", flags=("-O1",))
    inside = (TRAIN_C[0] + 1.0, TRAIN_C[1] - 1.0)
    for (lo, hi), clamped in ((inside, False), (_beyond(method), True)):
        accel, temp = _stream(lo, hi)
        state, golden = host.new_state(), golden_for(model.quantised)
        c_out = host.run(state, accel, temp)
        np.testing.assert_array_equal(c_out, golden.run(accel, temp))
        flags = int(host.read_state(state)["flags"])
        assert flags == golden.flags
        assert bool(flags & FLAG_INPUT_CLAMPED) == clamped, (method, lo, hi, flags)
        assert bool(flags & FLAG_TEMP_OUT_OF_RANGE) == clamped


def test_imu_module_flags_each_clamped_channel(rec: Recording, tmp_path: Path) -> None:
    """A cubic, a physics and a PLA channel in one module: the cubic and physics channels clip at the
    fitted range, PLA only at the front end's, so a sweep just beyond the fitted range flags two."""
    paths = []
    for method, channel in (("poly3", "accel0_x"), ("physics", "accel0_y"), ("pla", "accel0_z")):
        checkpoint = tm.checkpoint_for(method, rec)
        checkpoint["train_stats"] = {**checkpoint["train_stats"], "channel": channel, "unit": "mg"}
        paths.append(tmp_path / f"{channel}.pt")
        tm.save_checkpoint(checkpoint, paths[-1])
    from codegen.imu import export_imu

    imu, _ = export_imu(paths, tmp_path / "out", name="clampimu")
    imu = load_imu(paths)
    accel, temp = _stream(*_beyond("poly3"))
    raw = np.repeat(accel[:, None], 3, axis=1)
    out, flags, samples = host_run(tmp_path / "out", "clampimu", raw, temp[:, None], None, None)
    g_out, g_flags, g_samples = imu_golden(imu, raw, temp[:, None])
    np.testing.assert_array_equal(out, g_out)
    assert (flags, samples) == (g_flags, g_samples)
    assert [bool(f & FLAG_INPUT_CLAMPED) for f in flags] == [True, True, False]
    assert all(f & FLAG_TEMP_OUT_OF_RANGE for f in flags)


@pytest.mark.parametrize("method", ["poly3", "physics"])
def test_the_training_run_read_in_mdegc_is_inside_the_valid_range(method: str, tmp_path: Path) -> None:
    """The range's ends at a fraction of a mdegC (the bundled run's 73.96679 degC): the firmware reads
    them rounded to mdegC (73967), which must be neither flagged out of range nor clipped; a reading
    one mdegC beyond is flagged."""
    base = _training()
    temp = np.clip(base.temp_c, -10.00049, 49.96679)
    temp[0], temp[-1] = -10.00049, 49.96679
    rec = Recording({**base.columns, "temp_c": temp}, base.meta, "fraction-train")
    path = tmp_path / f"{method}.pt"
    tm.save_checkpoint(tm.checkpoint_for(method, rec), path)
    model, _ = export(path, tmp_path / "out", name="edge")
    host = load_module(tmp_path / "out", "edge", flags=("-O1",))
    read_mdegc = np.round(temp * 1000).astype(np.int32)
    assert (read_mdegc[0], read_mdegc[-1]) == (-10000, 49967)
    for stream, flagged in ((read_mdegc, False), (np.full(20, 49968, dtype=np.int32), True)):
        accel = np.zeros(stream.size, dtype=np.int32)
        state, golden = host.new_state(), golden_for(model.quantised)
        np.testing.assert_array_equal(host.run(state, accel, stream), golden.run(accel, stream))
        flags = int(host.read_state(state)["flags"])
        assert bool(flags & FLAG_TEMP_OUT_OF_RANGE) == flagged and bool(flags & FLAG_INPUT_CLAMPED) == flagged


@pytest.mark.parametrize("method", ["poly3", "pla", "physics", "dlstm-temp", "dlstm"])
def test_only_a_network_clamps_the_acceleration_and_the_manifest_says_which(
    method: str, rec: Recording, tmp_path: Path
) -> None:
    """16 g + 1 LSB: a recursive DLSTM clamps its network input, the acceleration (flagged); the cubic,
    PLA, physics and temperature-input DLSTM modules subtract the drift from the acceleration as it
    comes (no flag, the output one LSB above the output at full scale), and their manifest says
    `input_limits.input.clamped: false`."""
    import json

    path = tmp_path / f"{method}.pt"
    tm.save_checkpoint(tm.checkpoint_for(method, rec, hidden=4, layers=1), path)
    export(path, tmp_path / "out", name="full")
    manifest = json.loads((tmp_path / "out" / "full.manifest.json").read_text())
    clamps = method == "dlstm"
    signal = manifest["input_limits"]["input"]
    assert signal["clamped"] is clamps
    host = load_module(tmp_path / "out", "full", flags=("-O1",))
    full = 16 * 1000 * 16_000  # the default --accel-limit-g (docs/codegen.md), 16 g, in 1/16 ug
    if clamps:
        assert signal["lsb"] == [-full, full] and signal["range"] == [-16000.0, 16000.0]
    else:
        assert "lsb" not in signal
    temp = np.full(50, 20_000, dtype=np.int32)
    outputs = []
    for accel in (full, full + 1):
        state = host.new_state()
        outputs.append(host.run(state, np.full(50, accel, dtype=np.int32), temp))
        assert bool(int(host.read_state(state)["flags"]) & FLAG_INPUT_CLAMPED) == (clamps and accel > full)
    if not clamps:
        np.testing.assert_array_equal(outputs[1], outputs[0] + 1)
    # a full scale given for a module that never clamps is refused, not written into its manifest
    from codegen.cli import main as codegen_main
    from trainer.errors import run_cli

    argv = ["export", str(path), "-o", str(tmp_path / "two_g"), "--accel-limit-g", "2"]
    assert run_cli(codegen_main, argv) == (0 if clamps else 2)
    assert (tmp_path / "two_g").exists() == clamps
