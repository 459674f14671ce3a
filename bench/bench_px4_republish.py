"""What PX4's 1 degC republish rule costs on the bundled real run, next to the C module's error.

PX4's TemperatureCompensation applies the cubic at the temperature of its last publication, made
when the temperature had moved by more than 1 degC (``codegen/px4_republish.py``). This bench
imports the bundled chamber run (``trainer import ... --preset tofupilot --channels all``), fits
``poly3`` on every channel (``trainer fit --method poly3 --channels all``), replays each channel's
temperature through the rule and reports the applied correction minus the exact cubic (RMS, max;
the export's data-independent bound beside it). For accel z it also exports the fixed-point C
module and runs ``codegen verify``'s comparison (compiled C vs the float model), the figure the
C route costs instead. Numbers for docs/flight-stacks.md.

    python bench/bench_px4_republish.py
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
from bundled_run import REAL

from codegen.cli import main as codegen_main
from codegen.flightparams import load_channel_cubic
from codegen.px4_republish import lag_bound, republish_error
from codegen.verify import verify
from trainer import methods as registry
from trainer.baselines.poly3 import CubicPolynomial
from trainer.checkpoint import load_model
from trainer.cli import main as trainer_main
from trainer.data.channels import UNIT_LABELS
from trainer.data.recording_io import read_recording

CHANNELS = ("accel0_x", "accel0_y", "accel0_z", "gyro0_x", "gyro0_y", "gyro0_z")
C_MODULE_CHANNEL = "accel0_z"  # the recording's primary column, what a one-channel module verifies on


def main() -> int:
    if not REAL.is_file():
        print(f"real recording not found at {REAL}", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        recording, fit_dir = root / "imu.csv", root / "fit"
        assert (
            trainer_main(
                ["import", str(REAL), "--preset", "tofupilot", "--channels", "all", "-o", str(recording)]
            )
            == 0
        )
        assert (
            trainer_main(
                ["fit", "--method", registry.CUBIC, str(recording), "--channels", "all", "-o", str(fit_dir)]
            )
            == 0
        )
        rec = read_recording(recording)
        print("| channel | PX4 1 degC rule: RMS | max | bound (export's summary) |")
        print("| --- | --- | --- | --- |")
        for name in CHANNELS:
            model, _ = load_model(fit_dir / f"{name}.pt")
            assert isinstance(model, CubicPolynomial)
            cubic = load_channel_cubic(fit_dir / f"{name}.pt")
            unit = UNIT_LABELS[cubic.channel.unit]
            error = republish_error(model.drift_at, rec.temp_c)
            rms, worst = float(np.sqrt(np.mean(error**2))), float(np.max(np.abs(error)))
            bound = lag_bound(cubic, cubic.t_min_c, cubic.t_max_c)
            print(f"| {name} | {rms:.3g} {unit} | {worst:.3g} {unit} | {bound:.3g} {unit} |")
        out = root / "c"
        model_path = fit_dir / f"{C_MODULE_CHANNEL}.pt"
        assert codegen_main(["export", str(model_path), "-o", str(out)]) == 0
        budget = verify(model_path, out, recording, table1=False).budget
        print(
            f"C module ({C_MODULE_CHANNEL}, compiled, vs the float cubic): RMS {budget.rms_mg:.3g} mg, "
            f"max {budget.max_abs_mg:.3g} mg"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
