"""Does the scored data ramp faster than the training data did? (a sign-off note)

A compensator is fitted on the temperature rates its training run shows. The temperature range is
clamped and reported (coverage), but a model of thermal lag or of the temperature rate (physics,
the DLSTM) meets a faster ramp with no clamp: it extrapolates in rate. On the bundled real run,
physics trained on the last 80 % (ramps of 2-4 degC/min) and scored on the first 20 %, which
starts with 200 s at 7 degC/min, left 2.45 mg RMS over 60-200 s against the cubic's 0.92 mg, and
1.46 against 0.789 mg over the whole part (docs/real-data.md). The note says so where the reviewer reads the scores.
"""

from __future__ import annotations

import numpy as np

from trainer.data.holdout import training_part
from trainer.data.recording import Recording
from trainer.scoring.static import temperature_rate_c_per_min
from trainer.train_stats import TrainStats

RATE_PERCENTILE = 99.0  # the fastest ramp, robust to a few noisy slopes
RATE_MARGIN = 1.25  # the scored data's fastest ramp must exceed the training's by this factor


def fastest_ramp_c_per_min(rec: Recording) -> float:
    """The recording's fastest temperature ramp: the 99th percentile of |60 s slope|, degC/min."""
    rate = temperature_rate_c_per_min(np.asarray(rec.temp_c, dtype=np.float64), rec.sample_rate_hz)
    return float(np.percentile(np.abs(rate), RATE_PERCENTILE))


def rate_note(train_stats: TrainStats, scored: Recording, whole: Recording, what: str) -> str | None:
    """One line when ``scored`` ramps faster than the model's training rows (found in ``whole`` by
    content) by more than :data:`RATE_MARGIN`; None otherwise or when ``whole`` does not hold them."""
    train = training_part(train_stats, whole)
    if train is None or len(train) < 3 or len(scored) < 3:
        return None
    trained, seen = fastest_ramp_c_per_min(train), fastest_ramp_c_per_min(scored)
    if not seen > RATE_MARGIN * trained:
        return None
    return (
        f"temperature rate: the {what} ramps at up to {seen:.2g} degC/min, the training rows at up to "
        f"{trained:.2g}; a model of lag or rate (physics, the DLSTM) extrapolates in rate there, where the "
        "temperature clamp does not reach: train on the ramps the unit will meet"
    )
