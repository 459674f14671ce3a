"""The bundled real run as a user has it: imported with ``trainer import --preset tofupilot
--channels all -o imu.csv`` and read back from that CSV, the file every command then reads.

The CSV keeps 10 significant digits; the benches used the import's own float64 arrays instead,
and on one fold (gyro z, the first cooling held out) the physics finder's structure differs between
the two on 2026-11-30's VM (0.0369 against 0.0637 deg/s held out), so a bench would have printed a
figure no user gets (on 2026-12-02's both give 0.0369: that fold is on a knife edge, docs/real-data.md).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from trainer.data.importer import import_foreign, options_with_preset
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "tofupilot_imu_chamber_cycle.tsv"


def bundled_run() -> Recording:
    """Every channel of the bundled run, through the CSV ``trainer import`` writes."""
    rec = import_foreign(REAL, options_with_preset("tofupilot", channels=("all",)))
    with tempfile.TemporaryDirectory(prefix="bundled-run-") as tmp:
        path = Path(tmp) / "imu.csv"
        write_recording(rec, path)
        return read_recording(path)
