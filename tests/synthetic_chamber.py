"""Generated chamber runs for the finder's tests: a cubic bias, white noise and a small random walk
(seeded), plus catalogue effects added through the catalogue's own formulas
(``physics.effects.effect_contribution``)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from trainer.data.recording import Recording
from trainer.physics.effects import effect_contribution

FS_HZ = 2.0
DURATION_S = 4800.0
BLOCKS = 300  # 16 s blocks over DURATION_S: fast enough for a test, fine enough for the effects


def cycle_with_holds(t: np.ndarray) -> np.ndarray:
    """-10 -> 60 degC -> 20 degC, piecewise linear with holds (a reversal, two rates)."""
    return np.interp(
        t, [0.0, 600.0, 2200.0, 2800.0, 4200.0, DURATION_S], [-10.0, -10.0, 60.0, 60.0, 20.0, 20.0]
    )


def chamber_recording(
    effects: Sequence[tuple[str, dict[str, float]]],
    seed: int,
    temperature_c: Callable[[np.ndarray], np.ndarray] = cycle_with_holds,
    walk_mg: float = 0.004,
) -> Recording:
    """DURATION_S at FS_HZ of ``temperature_c(t)`` with the backbone above and ``effects`` added;
    ``walk_mg``: the random walk's step per sample (0: a quiet sensor, white noise only)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, DURATION_S, 1.0 / FS_HZ)
    temp = temperature_c(t)
    u = (temp - 25.0) / 50.0
    bias = 1.0 + 3.0 * u - 0.8 * u**2 + 0.5 * u**3
    white = 0.3 * rng.standard_normal(t.size)
    walk = np.cumsum(walk_mg * rng.standard_normal(t.size))
    added = sum((effect_contribution(e, p, t, temp, temp) for e, p in effects), np.zeros(t.size))
    columns = {
        "time_s": t,
        "temp_c": temp + 0.01 * rng.standard_normal(t.size),
        "accel_mg": bias + white + walk + added,
    }
    return Recording(columns, {"sample_rate_hz": str(FS_HZ)}, f"synthetic#{seed}")
