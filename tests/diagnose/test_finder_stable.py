"""Stable selection (issue 21): a finding of a recording survives an identifiable effect added elsewhere.

Synthetic recordings: a chamber cycle with a reversal, a cubic bias, white noise and a small random
walk (seeded), with a hysteresis and a bias step of their own (the "clean" findings), then the same
recording with a periodic component added through the catalogue's formula
(``physics.effects.effect_contribution``).
"""

from __future__ import annotations

import numpy as np

from trainer.data.recording import Recording
from trainer.diagnose import diagnose
from trainer.physics.catalogue import bias_step, hysteresis, periodic
from trainer.physics.effects import effect_contribution

STEP = bias_step.DEFINITION.identifier
HYSTERESIS = hysteresis.DEFINITION.identifier
PERIODIC = periodic.DEFINITION.identifier
FS_HZ = 2.0
DURATION_S = 4800.0
BLOCKS = 300  # 16 s blocks: fast enough for a test, fine enough for the effects below
OWN = [(HYSTERESIS, {"amp_mg": 0.4, "width_c": 5.0}), (STEP, {"t_s": 1500.0, "step_mg": 1.0})]
ADDED = (PERIODIC, {"amp_mg": 0.5, "period_s": 300.0, "phase_rad": 0.7})


def _temperature(t: np.ndarray) -> np.ndarray:
    """-10 -> 60 degC -> 20 degC, piecewise linear with holds (a reversal, two rates)."""
    knots_s = [0.0, 600.0, 2200.0, 2800.0, 4200.0, DURATION_S]
    knots_c = [-10.0, -10.0, 60.0, 60.0, 20.0, 20.0]
    return np.interp(t, knots_s, knots_c)


def _recording(effects: list[tuple[str, dict[str, float]]], seed: int) -> Recording:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, DURATION_S, 1.0 / FS_HZ)
    temp = _temperature(t)
    u = (temp - 25.0) / 50.0
    bias = 1.0 + 3.0 * u - 0.8 * u**2 + 0.5 * u**3
    white = 0.3 * rng.standard_normal(t.size)
    walk = np.cumsum(0.004 * rng.standard_normal(t.size))
    added = sum((effect_contribution(e, p, t, temp, temp) for e, p in effects), np.zeros(t.size))
    columns = {
        "time_s": t,
        "temp_c": temp + 0.01 * rng.standard_normal(t.size),
        "accel_mg": bias + white + walk + added,
    }
    return Recording(columns, {"sample_rate_hz": str(FS_HZ)}, f"synthetic#{seed}")


def _findings(rec: Recording) -> list[tuple[str, dict[str, float]]]:
    return [
        (e.effect, dict(e.params)) for e in diagnose(rec, holdout_fraction=0.0, max_blocks=BLOCKS).left_out
    ]


def test_findings_of_a_recording_survive_an_effect_added_elsewhere() -> None:
    """findings(clean) is a subset of findings(clean + periodic): same effects, a step at the same
    time (within two 16 s blocks), and the added periodic is named besides."""
    clean = _findings(_recording(OWN, seed=21))
    assert sorted(e for e, _ in clean) == sorted([HYSTERESIS, STEP])  # the recording's own findings
    added = _findings(_recording([*OWN, ADDED], seed=21))
    for effect, params in clean:
        same = [p for e, p in added if e == effect]
        assert same, f"{effect} of the clean recording is lost: {added}"
        if effect == STEP:
            assert any(abs(p["t_s"] - params["t_s"]) <= 2 * DURATION_S / BLOCKS for p in same)
    periods = [p["period_s"] for e, p in added if e == PERIODIC]
    assert any(abs(1 / p - 1 / ADDED[1]["period_s"]) <= 1 / DURATION_S for p in periods)
