"""A module of a gyroscope or barometer channel says so: the header's title names the sensor and the
channel, the manifest how its units read (the values are deg/s or Pa in the accel slots)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from codegen.export import export
from tests import testmodels as tm
from trainer.data.recording import Recording


@pytest.fixture(scope="module")
def rec() -> Recording:
    return tm.ramp_recording(3, "channel-train")


@pytest.mark.parametrize(
    ("channel", "unit", "title"),
    [
        ("gyro0_y", "dps", "gyroscope (channel gyro0_y, deg/s)"),
        ("baro0", "pa", "barometer (channel baro0, Pa)"),
        ("accel0_x", "mg", "accelerometer"),
    ],
)
def test_the_header_and_manifest_name_the_channel_s_sensor(
    channel: str, unit: str, title: str, rec: Recording, tmp_path: Path
) -> None:
    """A gyroscope model's module called itself "a MEMS accelerometer" and its manifest's units said
    only 1/16 micro-g: the title names the sensor and channel, the manifest how the units read."""
    checkpoint = tm.checkpoint_for("poly3", rec)
    checkpoint["train_stats"] = {**checkpoint["train_stats"], "channel": channel, "unit": unit}
    tm.save_checkpoint(checkpoint, tmp_path / "m.pt")
    export(tmp_path / "m.pt", tmp_path / "out", name="ch")
    header = (tmp_path / "out" / "ch.h").read_text()
    assert f"temperature-drift compensator of a MEMS {title}, method" in header
    units = json.loads((tmp_path / "out" / "ch.manifest.json").read_text())["units"]
    if unit == "mg":
        assert "channel" not in units
    else:
        assert units["channel"].startswith(title) and "1/16000" in units["channel"]
