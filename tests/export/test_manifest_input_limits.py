"""The one-channel manifest says what the module's C does, in the channel's own words.

A gyroscope module's manifest said ``accel_q4ug`` and "1/16 micro-g" while its header said
``rate_q16k`` and 1/16000 deg/s, and its ``input_limits`` said ``accel_g`` +-16 and a temperature clamp
of -100 .. 200 degC while the C clamped the temperature to the fitted range and never clamped the rate.
Here the expectations come from elsewhere: the step's prototype from NAME.h, the unit from the model
file, the temperature clamp from the model file's fitted range (cubic, physics) or the front end's
-100 .. 200 degC (docs/codegen.md), and what the limits mean from the compiled C's own flag at their
edges.
"""

from __future__ import annotations

import json
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from codegen.export import export
from codegen.fixedpoint import INT32_MAX, round_half_away
from codegen.hostbuild import load_module
from codegen.quantize import FLAG_INPUT_CLAMPED
from tests import testmodels as tm
from trainer.data.channels import UNIT_LABELS
from trainer.data.recording import Recording

FRONT_END_MDEGC = [-100_000, 200_000]  # docs/codegen.md: PLA and the temperature-input DLSTM clamp T here
LSB_PER_UNIT = 16_000  # docs/codegen.md: one LSB is 1/16000 of the channel's unit
# docs/codegen.md: where a network of the raw input clamps it by default, in the channel's unit:
# --accel-limit-g 16 (16000 mg), --gyro-limit-dps 2000, and a barometer (no option) at 128000 Pa
DEFAULT_FULL_SCALE = {"mg": 16 * 1000, "dps": 2000, "pa": 128_000}

CASES = [  # (method, channel, unit in the model file)
    ("poly3", "gyro0_x", "dps"),
    ("poly3", "baro0", "pa"),
    ("poly3", "accel0_x", "mg"),
    ("pla", "gyro0_y", "dps"),
    ("physics", "gyro0_x", "dps"),
    ("physics", "baro0", "pa"),
    ("dlstm-temp", "gyro0_z", "dps"),
    ("dlstm", "gyro0_x", "dps"),
    ("dlstm", "accel0_z", "mg"),
    ("persistence", "accel0_y", "mg"),
    ("persistence", "gyro0_y", "dps"),
    ("persistence", "baro0", "pa"),  # made by hand: the trainer refuses the recursive methods on a barometer
]


@pytest.fixture(scope="module")
def rec() -> Recording:
    return tm.ramp_recording(11, "limits-train")


def _export(method: str, channel: str, unit: str, rec: Recording, tmp_path: Path) -> dict[str, object]:
    checkpoint = tm.checkpoint_for(method, rec, hidden=4, layers=2)
    checkpoint["train_stats"] = {**checkpoint["train_stats"], "channel": channel, "unit": unit}
    tm.save_checkpoint(checkpoint, tmp_path / "m.pt")
    export(tmp_path / "m.pt", tmp_path / "out", name="lim")
    return checkpoint


def _one_line(text: str) -> str:
    return " ".join(text.split())


@pytest.mark.parametrize(("method", "channel", "unit"), CASES)
def test_api_and_units_are_the_header_s_in_the_channel_s_unit(
    method: str, channel: str, unit: str, rec: Recording, tmp_path: Path
) -> None:
    _export(method, channel, unit, rec, tmp_path)
    header = _one_line((tmp_path / "out" / "lim.h").read_text())
    manifest = json.loads((tmp_path / "out" / "lim.manifest.json").read_text())
    for function in ("step", "run"):
        declared = re.search(rf"(\S+ lim_{function}\([^)]*\));", header)
        assert declared is not None, function
        assert manifest["api"][function] == declared.group(1)
    argument = re.search(r"lim_step\(lim_state_t \*state, int32_t (\w+), int32_t temp_mdegc\)", header)
    assert argument is not None
    label = UNIT_LABELS[unit]
    units = manifest["units"]
    assert units["unit"] == label and units["lsb_per_unit"] == 16_000
    assert units["in"].startswith(f"{argument.group(1)}: ")
    if unit == "mg":  # 1/16 micro-g, as the header says it
        assert "1/16 micro-g" in units["in"] and "1/16 ug" in units["out"]
    else:
        assert f"1/16000 {label}" in units["in"] and f"1/16000 {label}" in units["out"]
        assert "micro-g" not in json.dumps(units) and "accel" not in json.dumps(manifest["api"])
    assert manifest["input_limits"]["input"]["argument"] == argument.group(1)


def _expected_temp_clamp(method: str, checkpoint: dict[str, object]) -> list[int] | None:
    """Where the docs say each family clamps T: the fitted range (cubic, physics; read as the firmware
    reads it, rounded to mdegC), the front end's range (PLA, temperature-input DLSTM), nowhere (a
    network whose input is the raw signal reads T only for the valid-range flag)."""
    if method in ("poly3", "physics"):
        lo, hi = checkpoint["valid_temp_range_c"]  # type: ignore[misc]
        return [round_half_away(Fraction(lo) * 1000), round_half_away(Fraction(hi) * 1000)]
    if method in ("pla", "dlstm-temp"):
        return FRONT_END_MDEGC
    return None


@pytest.mark.parametrize(("method", "channel", "unit"), CASES)
def test_input_limits_are_where_the_c_clamps(
    method: str, channel: str, unit: str, rec: Recording, tmp_path: Path
) -> None:
    checkpoint = _export(method, channel, unit, rec, tmp_path)
    limits = json.loads((tmp_path / "out" / "lim.manifest.json").read_text())["input_limits"]
    host = load_module(tmp_path / "out", "lim", flags=("-O1",))

    def clamped(raw: int, temp_mdegc: int) -> bool:
        state = host.new_state()
        host.run(state, np.full(30, raw, dtype=np.int32), np.full(30, temp_mdegc, dtype=np.int32))
        return bool(int(host.read_state(state)["flags"]) & FLAG_INPUT_CLAMPED)

    inside_t = 20_000  # mdegC, inside every model's range
    expected_t = _expected_temp_clamp(method, checkpoint)
    temp = limits["temp"]
    assert temp["clamped"] is (expected_t is not None)
    if expected_t is None:
        assert "mdegc" not in temp
        assert not clamped(0, -(2**31) + 1) and not clamped(0, INT32_MAX)
    else:
        assert temp["mdegc"] == expected_t
        lo, hi = expected_t
        assert not clamped(0, lo) and not clamped(0, hi)
        assert clamped(0, lo - 1) and clamped(0, hi + 1)

    signal = limits["input"]
    label = UNIT_LABELS[unit]
    assert signal["unit"] == label
    if method in ("dlstm", "persistence"):  # a network (or window mean) of the raw input clamps it
        full_scale = DEFAULT_FULL_SCALE[unit]
        full = full_scale * LSB_PER_UNIT
        assert signal["clamped"] is True
        assert signal["lsb"] == [-full, full]
        assert signal["range"] == [-full_scale, full_scale]  # in the channel's unit
        assert not clamped(full, inside_t) and not clamped(-full, inside_t)
        assert clamped(full + 1, inside_t) and clamped(-full - 1, inside_t)
        one_unit_more = (full_scale + 1) * LSB_PER_UNIT  # 16001 mg, 2001 deg/s
        assert clamped(one_unit_more, inside_t) and clamped(-one_unit_more, inside_t)
    else:
        assert signal["clamped"] is False and "lsb" not in signal and "range" not in signal
        assert not clamped(INT32_MAX, inside_t) and not clamped(-INT32_MAX, inside_t)


def test_the_flag_comment_in_the_header_names_the_same_clamps(rec: Recording, tmp_path: Path) -> None:
    """NAME.h's comment of NAME_FLAG_INPUT_CLAMPED says where this module clamps, as the manifest."""
    _export("physics", "gyro0_x", "dps", rec, tmp_path)
    header = (tmp_path / "out" / "lim.h").read_text()
    lo, hi = json.loads((tmp_path / "out" / "lim.manifest.json").read_text())["input_limits"]["temp"]["mdegc"]
    flag = next(line for line in header.splitlines() if "LIM_FLAG_INPUT_CLAMPED" in line)
    assert f"temp_mdegc to {lo} .. {hi}" in flag and "rate_q16k is never clamped" in flag
