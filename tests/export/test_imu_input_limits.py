"""The IMU module's manifest says, per channel, where the module's C clamps its inputs (docs/imu-module.md).

A module of six channels on two sensors at 5 Hz: accel0_x physics (every C term), accel0_y a cubic
whose fitted range is narrower than the sensor's valid range, accel0_z a recursive DLSTM, gyro0_x a
piecewise-linear model, gyro0_y a temperature-input DLSTM and gyro0_z a recursive DLSTM, exported
with ``--accel-limit-g 4 --gyro-limit-dps 500``. The expected limits come from elsewhere than the
code under test: the model files (a cubic's and a physics model's fitted range, read in mdegC as the
firmware reads it), docs/codegen.md (PLA and the temperature-input DLSTM clamp T at the front end's
-100 .. 200 degC; a recursive DLSTM clamps its raw input at the limit of its unit, --accel-limit-g in
g for an accelerometer channel, --gyro-limit-dps in deg/s for a gyroscope channel, and reads T only
for the valid-range flag; every other channel subtracts its drift from the raw input as it comes). What the limits mean is
checked on the compiled C itself: inputs at a stated limit are not flagged, inputs beyond it set the
channel's input-clamped flag and give what the limit gives, and an input said never to be clamped
is not flagged however large.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from codegen.fixedpoint import round_half_away
from codegen.imu_verify import load_host_module, verify_imu
from codegen.quantize import FLAG_INPUT_CLAMPED
from tests import testmodels as tm
from trainer.data.channels import UNIT_LABELS
from trainer.data.recording import Recording

NAME = "imu0"
RATE_HZ = 5.0
I32_MIN, I32_MAX = -(2**31), 2**31 - 1
FRONT_END_MDEGC = (-100_000, 200_000)  # docs/codegen.md: PLA and the temperature-input DLSTM clamp T here
ACCEL_LIMIT_G = 4.0
GYRO_LIMIT_DPS = 500.0
# each recursive DLSTM's raw-input limit in its channel's unit: 4 g = 4000 mg, 500 deg/s
FULL_SCALE_UNITS = {"mg": ACCEL_LIMIT_G * 1000, "dps": GYRO_LIMIT_DPS}
LSB_PER_UNIT = 16_000  # docs/imu-module.md: raw and out in 1/16000 of the channel's unit
CUBIC_RANGE_C = (-20.0, 60.0)  # the cubic's fitted range, wider than its sensor's valid range
# (method, channel, unit): the module's order
CHANNELS = (
    ("physics", "accel0_x", "mg"),
    ("poly3", "accel0_y", "mg"),
    ("dlstm", "accel0_z", "mg"),
    ("pla", "gyro0_x", "dps"),
    ("dlstm-temp", "gyro0_y", "dps"),
    ("dlstm", "gyro0_z", "dps"),
)
SENSORS = ("accel0", "gyro0")
STEPS = 30  # samples per probe: six network steps of a DLSTM (one per second)
INSIDE_MDEGC = 20_000  # inside every channel's range


def recording() -> Recording:
    return tm.ramp_recording(4, "imu-limits", rate_hz=RATE_HZ, temp_noise_c=0.01)


def mdegc(value_c: float) -> int:
    """A range end in degC read as the firmware reads it: rounded half away from zero to mdegC."""
    return round_half_away(Fraction(value_c) * 1000)


@dataclass(frozen=True)
class Expected:
    temp: tuple[int, int] | None  # mdegC, None: never clamped
    signal: int | None  # +-LSB, None: never clamped


@dataclass(frozen=True)
class Module:
    out: Path
    manifest: dict[str, Any]
    header: str
    expected: list[Expected]
    ffi: Any
    lib: Any


def expected_limits(method: str, unit: str, checkpoint: dict[str, Any]) -> Expected:
    """Where the docs say each family clamps, read from the model file."""
    full_scale = round(FULL_SCALE_UNITS[unit] * LSB_PER_UNIT)
    if method == "physics":
        lo, hi = checkpoint["payload"]["temp_range_c"]
        return Expected((mdegc(lo), mdegc(hi)), None)
    if method == "poly3":
        lo, hi = checkpoint["payload"]["temp_range_c"]
        return Expected((mdegc(lo), mdegc(hi)), None)
    if method in ("pla", "dlstm-temp"):
        return Expected(FRONT_END_MDEGC, None)
    assert method == "dlstm"
    return Expected(None, full_scale)


@pytest.fixture(scope="module")
def module(tmp_path_factory: pytest.TempPathFactory) -> Module:
    root = tmp_path_factory.mktemp("imu-limits")
    rec = recording()
    paths, expected = [], []
    for seed, (method, channel, unit) in enumerate(CHANNELS):
        checkpoint = tm.checkpoint_for(method, rec, hidden=4, layers=2, seed=seed)
        if method == "poly3":
            checkpoint["payload"]["temp_range_c"] = list(CUBIC_RANGE_C)
        checkpoint["train_stats"] = {**checkpoint["train_stats"], "channel": channel, "unit": unit}
        paths.append(root / f"{channel}.pt")
        tm.save_checkpoint(checkpoint, paths[-1])
        expected.append(expected_limits(method, unit, checkpoint))
    out = root / "c"
    argv = [
        "export",
        *map(str, paths),
        "-o",
        str(out),
        "--name",
        NAME,
        "--accel-limit-g",
        f"{ACCEL_LIMIT_G:g}",
        "--gyro-limit-dps",
        f"{GYRO_LIMIT_DPS:g}",
    ]
    assert codegen_main(argv) == 0
    manifest = json.loads((out / f"{NAME}.manifest.json").read_text())
    ffi, lib = load_host_module(out, NAME, flags=("-O1",))
    return Module(out, manifest, (out / f"{NAME}.h").read_text(), expected, ffi, lib)


def probe(m: Module, channel: int, raw: int, temp_mdegc: int) -> tuple[np.ndarray, int]:
    """STEPS samples from NAME_init of the built-in calibration: ``raw`` on ``channel`` (0 on the
    others) and ``temp_mdegc`` on its sensor (the other sensor inside every range). The channel's
    outputs and its flags."""
    sensor = SENSORS.index(CHANNELS[channel][1][:-2])
    raw_row = np.zeros(len(CHANNELS), dtype=np.int32)
    raw_row[channel] = raw
    temp_row = np.full(len(SENSORS), INSIDE_MDEGC, dtype=np.int32)
    temp_row[sensor] = temp_mdegc
    state = m.ffi.new(f"{NAME}_state_t *")
    m.lib.imu0_init(state, m.lib.imu0_builtin())
    out = m.ffi.new("int32_t[]", len(CHANNELS))
    r = m.ffi.from_buffer("int32_t[]", raw_row)
    t = m.ffi.from_buffer("int32_t[]", temp_row)
    outputs = np.empty(STEPS, dtype=np.int64)
    for k in range(STEPS):
        m.lib.imu0_step(state, r, t, out)
        outputs[k] = out[channel]
    return outputs, int(state.flags[channel])


def clamped(m: Module, channel: int, raw: int, temp_mdegc: int) -> bool:
    return bool(probe(m, channel, raw, temp_mdegc)[1] & FLAG_INPUT_CLAMPED)


def test_the_manifest_states_each_channels_clamps_as_the_model_files_and_docs_say(module: Module) -> None:
    m = module.manifest
    assert m["format"] == "mems-tdc-imu-module" and m["format_version"] == 2
    assert [c["name"] for c in m["channels"]] == [c for _, c, _ in CHANNELS]
    for entry, (_, channel, unit), expected in zip(m["channels"], CHANNELS, module.expected, strict=True):
        limits = entry["input_limits"]
        signal, temp = limits["input"], limits["temp"]
        sensor = channel[:-2]
        # the arguments are the IMU step's, indexed by the header's own macros
        assert signal["argument"] == f"raw[IMU0_CH_{channel.upper()}]"
        assert temp["argument"] == f"temp_mdegc[IMU0_SENSOR_{sensor.upper()}]"
        assert re.search(rf"#define IMU0_CH_{channel.upper()} \d+u", module.header)
        assert re.search(rf"#define IMU0_SENSOR_{sensor.upper()} \d+u", module.header)
        assert signal["unit"] == UNIT_LABELS[unit] == entry["unit"]
        if expected.temp is None:
            assert temp["clamped"] is False and "mdegc" not in temp and "never" in temp["note"]
        else:
            assert temp["clamped"] is True and temp["mdegc"] == list(expected.temp), channel
        if expected.signal is None:
            assert signal["clamped"] is False and "lsb" not in signal and "never" in signal["note"]
        else:
            full = expected.signal
            assert signal["clamped"] is True
            assert signal["lsb"] == [-full, full]
            assert signal["range"] == [-full / LSB_PER_UNIT, full / LSB_PER_UNIT]  # 4000 mg, 500 deg/s
            assert signal["range"][1] == {"mg": 4000.0, "dps": 500.0}[unit]
    # the cubic's clamp is its own fitted range, not its sensor's valid range
    valid = next(s for s in m["sensors"] if s["name"] == "accel0")["valid_temp_range_mdegc"]
    assert m["channels"][1]["input_limits"]["temp"]["mdegc"] != valid


@pytest.mark.parametrize("index", range(len(CHANNELS)), ids=[c for _, c, _ in CHANNELS])
def test_the_c_clamps_the_temperature_exactly_at_the_stated_limits(module: Module, index: int) -> None:
    temp = module.manifest["channels"][index]["input_limits"]["temp"]
    raw = 3 * LSB_PER_UNIT  # inside every raw limit
    if not temp["clamped"]:
        for t in (I32_MIN, -(2**31) + 1, I32_MAX):
            assert not clamped(module, index, raw, t), t
        return
    lo, hi = temp["mdegc"]
    for edge, beyond in ((lo, (lo - 1, lo - 1000, I32_MIN)), (hi, (hi + 1, hi + 1000, I32_MAX))):
        at_edge, flags = probe(module, index, raw, edge)
        assert not flags & FLAG_INPUT_CLAMPED, edge
        for t in beyond:
            out, flags = probe(module, index, raw, t)
            assert flags & FLAG_INPUT_CLAMPED, t
            np.testing.assert_array_equal(out, at_edge, err_msg=f"{CHANNELS[index][1]} at {t} mdegC")
    # just inside: not flagged either
    for t in (lo + 1, hi - 1):
        assert not clamped(module, index, raw, t)


@pytest.mark.parametrize("index", range(len(CHANNELS)), ids=[c for _, c, _ in CHANNELS])
def test_the_c_clamps_the_raw_input_exactly_at_the_stated_limits(module: Module, index: int) -> None:
    signal = module.manifest["channels"][index]["input_limits"]["input"]
    if not signal["clamped"]:
        for raw in (I32_MAX, -I32_MAX, I32_MIN):
            assert not clamped(module, index, raw, INSIDE_MDEGC), raw
        return
    lo, hi = signal["lsb"]
    for edge, beyond in ((lo, (lo - 1, 2 * lo)), (hi, (hi + 1, 2 * hi))):
        at_edge, flags = probe(module, index, edge, INSIDE_MDEGC)
        assert not flags & FLAG_INPUT_CLAMPED, edge
        assert not clamped(module, index, edge - np.sign(edge), INSIDE_MDEGC)  # just inside
        for raw in beyond:
            out, flags = probe(module, index, raw, INSIDE_MDEGC)
            assert flags & FLAG_INPUT_CLAMPED, raw
            assert np.all(np.abs(out) < I32_MAX)  # the output is raw - drift, not saturated
            # the model reads the limit: the same drift estimate, subtracted from the raw input as it came
            np.testing.assert_array_equal(
                raw - out, edge - at_edge, err_msg=f"{CHANNELS[index][1]} raw {raw}"
            )
        for raw in (I32_MAX, I32_MIN):
            assert clamped(module, index, raw, INSIDE_MDEGC)


def test_the_header_names_each_channels_clamps_as_the_manifest(module: Module) -> None:
    lines = [line.split("clamps:", 1)[1].strip() for line in module.header.splitlines() if "clamps:" in line]
    assert len(lines) == len(module.manifest["channels"])  # one per channel, in the module's order
    for line, entry in zip(lines, module.manifest["channels"], strict=True):
        signal, temp = entry["input_limits"]["input"], entry["input_limits"]["temp"]
        if temp["clamped"]:
            lo, hi = temp["mdegc"]
            assert f"{temp['argument']} to {lo} .. {hi}" in line, entry["name"]
        if signal["clamped"]:
            lo, hi = signal["lsb"]
            assert lo == -hi, entry["name"]
            limit = f"+-{hi / LSB_PER_UNIT:g} {signal['unit']}"
            assert f"{signal['argument']} to +-{hi} ({limit})" in line, entry["name"]
        for side in (temp, signal):
            assert (f"{side['argument']} is never clamped" in line) == (not side["clamped"]), entry["name"]


def test_a_data_only_module_clamps_at_the_blobs_records_as_its_manifest_states(tmp_path: Path) -> None:
    """--blob: the cubic and PLA channels' clamps are in the blob's channel records; the manifest
    exported with that blob states them, and the C loaded with it clamps there."""
    rec = recording()
    paths = []
    for method, channel, unit in (("poly3", "accel0_y", "mg"), ("pla", "gyro0_x", "dps")):
        checkpoint = tm.checkpoint_for(method, rec)
        if method == "poly3":
            checkpoint["payload"]["temp_range_c"] = list(CUBIC_RANGE_C)
        checkpoint["train_stats"] = {**checkpoint["train_stats"], "channel": channel, "unit": unit}
        paths.append(tmp_path / f"{channel}.pt")
        tm.save_checkpoint(checkpoint, paths[-1])
    out = tmp_path / "c"
    assert codegen_main(["export", *map(str, paths), "-o", str(out), "--name", NAME, "--blob"]) == 0
    manifest = json.loads((out / f"{NAME}.manifest.json").read_text())
    assert manifest["calibration"]["builtin"] is False
    limits = [c["input_limits"]["temp"]["mdegc"] for c in manifest["channels"]]
    assert limits == [[mdegc(CUBIC_RANGE_C[0]), mdegc(CUBIC_RANGE_C[1])], list(FRONT_END_MDEGC)]
    ffi, lib = load_host_module(out, NAME, flags=("-O1",))
    blob = (out / f"{NAME}.cal.bin").read_bytes()
    cal = ffi.new(f"{NAME}_calibration_t *")
    assert lib.imu0_load(cal, ffi.from_buffer("uint8_t[]", blob), len(blob)) == 0
    for k, (lo, hi) in enumerate(limits):
        for t, flagged in ((lo, False), (hi, False), (lo - 1, True), (hi + 1, True)):
            state = ffi.new(f"{NAME}_state_t *")
            lib.imu0_init(state, cal)
            temp = ffi.new("int32_t[]", [t, t])
            lib.imu0_step(state, ffi.new("int32_t[]", [0, 0]), temp, ffi.new("int32_t[]", 2))
            assert bool(state.flags[k] & FLAG_INPUT_CLAMPED) is flagged, (manifest["channels"][k]["name"], t)


def test_codegen_verify_reads_the_raw_input_limit_the_module_was_exported_with(
    module: Module, tmp_path: Path
) -> None:
    """The module clamps its recursive DLSTMs' raw inputs at different limits per unit, 4 g
    (--accel-limit-g 4) and 500 deg/s (--gyro-limit-dps 500): verify builds each channel's golden
    model with the limit its manifest states, so a recording beyond both (up to 6 g, 6000 deg/s) is
    still 0 mismatches on every channel."""
    n = 600
    rng = np.random.default_rng(8)
    temp = np.linspace(-5.0, 45.0, n)
    columns: dict[str, np.ndarray] = {"time_s": np.arange(n) / RATE_HZ, "temp_c": temp}
    for _, channel, unit in CHANNELS:
        columns[f"{channel}_{unit}"] = rng.uniform(-6000.0, 6000.0, n)
    columns["accel_mg"] = columns["accel0_x_mg"]
    rec = Recording(columns, {"sample_rate_hz": f"{RATE_HZ:g}", "channel": "accel0_x"}, "beyond-4g")
    models = sorted(module.out.parent.glob("*.pt"))
    result = verify_imu(models, module.out, rec)
    assert [r.target for r in result.runs] == ["host"]
    assert result.runs[0].mismatches == [0] * len(CHANNELS) and result.runs[0].state_equal
    flags = [probe(module, k, 5 * LSB_PER_UNIT * 1000, INSIDE_MDEGC)[1] for k in (2, 5)]
    assert all(f & FLAG_INPUT_CLAMPED for f in flags)  # 5000 units: beyond the limit, clamped


def test_the_header_says_which_channels_hold_their_edge_beyond_the_valid_range(module: Module) -> None:
    """``NAME_CH_<channel>_HOLDS_EDGE_BEYOND_RANGE`` against the compiled C: at two temperatures beyond
    each end of the channel's valid range (the model file's), with two different raw inputs, a channel
    that holds its edge subtracts the same correction (its edge's); one that extrapolates, reads the
    temperature beyond the valid range (the cubic fitted wider than it) or reads the raw input does not."""
    from trainer.checkpoint import load_checkpoint

    said = {
        name.lower(): int(value)
        for name, value in re.findall(
            rf"#define {NAME.upper()}_CH_(\w+)_HOLDS_EDGE_BEYOND_RANGE (\d)u", module.header
        )
    }
    assert sorted(said) == sorted(c for _, c, _ in CHANNELS)
    for index, (method, channel, _) in enumerate(CHANNELS):
        if (
            method == "dlstm"
        ):  # docs/codegen.md: its input is the raw signal, read as it comes, never a held edge
            assert said[channel] == 0, (
                channel
            )  # (the test's tiny network gives one estimate whatever it reads)
            continue
        lo_c, hi_c = load_checkpoint(module.out.parent / f"{channel}.pt")["valid_temp_range_c"]
        corrections = []
        for raw, beyond in ((3 * LSB_PER_UNIT, 3_000), (2_000 * LSB_PER_UNIT, 9_000)):
            for end in (mdegc(lo_c) - beyond, mdegc(hi_c) + beyond):
                out, _ = probe(module, index, raw, end)
                corrections.append(raw - out[-1])
        holds = corrections[0] == corrections[2] and corrections[1] == corrections[3]
        assert said[channel] == int(holds), (method, channel, corrections)
    assert set(said.values()) == {0, 1}  # the module has both kinds (physics holds; PLA extrapolates)
