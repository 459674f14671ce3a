"""The sign-off says when the scored data ramps faster than the training rows did: a model of lag
or rate extrapolates there, where the temperature clamp does not reach."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from trainer.cli import main
from trainer.data.holdout import parse_holdout, split
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording
from trainer.scoring.rate_coverage import RATE_MARGIN, fastest_ramp_c_per_min

RATE_HZ = 2.0


def ramps(*legs: tuple[float, float]) -> Recording:
    """A chamber run from 0 degC through ``legs`` (end temperature degC, rate degC/min), with a
    quadratic drift and white noise."""
    temps = [np.array([0.0])]
    for end, rate in legs:
        start = float(temps[-1][-1])
        n = round(abs(end - start) / rate * 60.0 * RATE_HZ)
        temps.append(np.linspace(start, end, n + 1)[1:])
    temp = np.concatenate(temps)
    rng = np.random.default_rng(5)
    d = temp - 20.0
    columns = {
        "time_s": np.arange(temp.size) / RATE_HZ,
        "temp_c": temp,
        "accel_mg": 0.3 * d + 2e-3 * d**2 + rng.normal(0.0, 0.05, temp.size),
    }
    return Recording(columns, {"sample_rate_hz": str(RATE_HZ)}, "ramps")


def test_the_fastest_ramp_is_the_ramp_rate_built_in() -> None:
    assert fastest_ramp_c_per_min(ramps((40.0, 1.0), (0.0, 4.0))) == pytest.approx(4.0, rel=0.02)
    assert fastest_ramp_c_per_min(ramps((40.0, 1.0))) == pytest.approx(1.0, rel=0.02)


@pytest.mark.parametrize(("fast_c_per_min", "noted"), [(5.0, True), (1.0, False)])
def test_report_notes_a_held_out_part_that_ramps_faster_than_training(
    tmp_path: Path, fast_c_per_min: float, noted: bool
) -> None:
    run = ramps((40.0, 1.0), (0.0, 1.0), (40.0, fast_c_per_min))  # two slow ramps, then the last one
    write_recording(run, tmp_path / "run.csv")
    holdout = "4800:"  # the two slow ramps take 2 x 40 min
    train, held = split(read_recording(tmp_path / "run.csv"), parse_holdout(holdout))
    assert float(held.temp_c[0]) == pytest.approx(0.0, abs=0.1)  # the held-out part is the last ramp
    write_recording(train, tmp_path / "train.csv")
    assert main(["fit", "--method", "poly3", str(tmp_path / "train.csv"), "-o", str(tmp_path / "m.pt")]) == 0
    code = main(
        [
            "report",
            str(tmp_path / "m.pt"),
            "--recording",
            str(tmp_path / "run.csv"),
            "--holdout",
            holdout,
            "-o",
            str(tmp_path / "so"),
        ]
    )
    assert code in (0, 1)
    text = (tmp_path / "so" / "report.md").read_text(encoding="utf-8")
    assert ("temperature rate: the held-out part ramps at up to" in text) is noted
    if noted:
        assert fast_c_per_min > RATE_MARGIN * 1.0
        assert f"up to {fast_c_per_min:.2g} degC/min, the training rows at up to 1" in text
