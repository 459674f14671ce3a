"""SHA-256 of every file `codegen export` writes for the frozen reference models (tests/data/ref).

A refactor of codegen/ must leave the exports byte-identical: run this before and after and diff
the two listings.

    python scripts/export_fingerprints.py > before.txt   # ... change ...
    python scripts/export_fingerprints.py > after.txt && diff before.txt after.txt

Exports: each reference model as its own C module (and with ``--schedule spread`` for the DLSTMs),
the cubic as PX4 and ArduPilot parameters, and one IMU module (and its calibration blob) holding
one channel of each reference model that an IMU module takes (the blob: its cubic and PLA channels).
"""

from __future__ import annotations

import hashlib
import sys
import tempfile
from contextlib import redirect_stdout
from io import StringIO
from pathlib import Path

from codegen.cli import main as codegen
from tests.testmodels import save_checkpoint
from trainer.checkpoint import load_checkpoint
from trainer.errors import run_cli

REF = Path(__file__).resolve().parents[1] / "tests" / "data" / "ref"
# One channel per reference model in the IMU module (names of the recording format).
IMU_CHANNELS = {
    "poly3": "accel0_x",
    "pla": "accel0_y",
    "physics": "accel0_z",
    "dlstm-temp": "gyro0_x",
    "dlstm": "gyro0_y",
}


def _export(out: Path, *argv: str) -> str:
    with redirect_stdout(StringIO()):
        code = run_cli(codegen, ["export", *argv, "-o", str(out)])
    return "ok" if code == 0 else f"exit {code}"


def _listing(label: str, out: Path, status: str) -> list[str]:
    if status != "ok":
        return [f"{label}: {status}"]
    return [
        f"{label}/{p.relative_to(out)} {hashlib.sha256(p.read_bytes()).hexdigest()}"
        for p in sorted(out.rglob("*"))
        if p.is_file()
    ]


def main() -> None:
    lines: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        models = sorted(REF.glob("*.pt"))
        for model in models:
            name = model.stem
            out = root / f"{name}-c"
            lines += _listing(f"{name} c", out, _export(out, str(model), "--name", "tdc_ref"))
            if name.startswith("dlstm"):
                out = root / f"{name}-spread"
                status = _export(out, str(model), "--name", "tdc_ref", "--schedule", "spread")
                lines += _listing(f"{name} spread", out, status)
        for fmt in ("px4-params", "ardupilot-parm"):
            out = root / f"poly3-{fmt}"
            status = _export(
                out,
                str(REF / "poly3.pt"),
                "--format",
                fmt,
                "--channel",
                "accel0_z",
                "--device-id",
                "accel0=1310988",
            )
            lines += _listing(f"poly3 {fmt}", out, status)
        imu_dir = root / "imu-models"
        imu_dir.mkdir()
        for method, channel in IMU_CHANNELS.items():
            checkpoint = load_checkpoint(REF / f"{method}.pt")
            unit = "dps" if channel.startswith("gyro") else "mg"
            checkpoint["train_stats"] = {**checkpoint["train_stats"], "channel": channel, "unit": unit}
            save_checkpoint(checkpoint, imu_dir / f"{channel}.pt")
        out = root / "imu-c"
        lines += _listing("imu c", out, _export(out, str(imu_dir), "--channels", "all", "--name", "tdc_imu"))
        blob_channels = ",".join(
            c for m, c in IMU_CHANNELS.items() if m in ("poly3", "pla")
        )  # blob records: cubic and PLA
        out = root / "imu-blob"
        status = _export(out, str(imu_dir), "--channels", blob_channels, "--name", "tdc_imu", "--blob")
        lines += _listing("imu blob", out, status)
    sys.stdout.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
