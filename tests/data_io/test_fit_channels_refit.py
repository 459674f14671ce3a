"""``trainer fit --channels`` into a directory an earlier fit wrote: the new set replaces the old one.

Fitted with ``--channels all`` and then with ``--channels gyro0_x`` into the same directory, the
directory held the new index (gyro x only) beside the old accel z model, which the index no longer
listed: ``codegen export DIR --channels accel0_z`` said there was no such model while the file was
there. The models the earlier index listed go; a file of the user's stays.
"""

from __future__ import annotations

import json
from pathlib import Path

from tests.imu_checks import accel_gyro_columns
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording


def test_a_refit_of_fewer_channels_leaves_no_model_of_the_earlier_set(tmp_path: Path) -> None:
    rec = tmp_path / "imu.csv"
    write_recording(Recording(accel_gyro_columns(4), {"sample_rate_hz": "2"}, "imu"), rec)
    out = tmp_path / "fit"
    assert trainer_main(["fit", "--method", "poly3", str(rec), "--channels", "all", "-o", str(out)]) == 0
    assert {p.name for p in out.glob("*.pt")} == {"accel0_z.pt", "gyro0_x.pt"}
    (out / "notes.txt").write_text("the user's own file\n")
    assert trainer_main(["fit", "--method", "pla", str(rec), "--channels", "gyro0_x", "-o", str(out)]) == 0
    index = json.loads((out / "channels.json").read_text())
    assert [c["channel"] for c in index["channels"]] == ["gyro0_x"]
    assert {p.name for p in out.glob("*.pt")} == {"gyro0_x.pt"}
    assert (out / "notes.txt").read_text() == "the user's own file\n"
