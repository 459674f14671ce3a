"""The true input along the axis (``g_in_mg``): zero, a constant, a step sequence or manoeuvres.

The simulator adds it to the output; the mismatch finder evaluates the user's known input with
the same function so both see the same signal.
"""

from __future__ import annotations

import numpy as np

from trainer.physics.config import InputConfig
from trainer.physics.noise import gauss_markov


def input_signal(cfg: InputConfig, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """True input ``g_in_mg(t)`` along the sensitive axis.

    - ``zero``: the paper's static test (axis perpendicular to gravity).
    - ``constant``: ``value_mg`` (a tilt or misalignment component of gravity).
    - ``steps``: ``value_mg`` of the latest step with ``t_s <= t``, 0 before the first (a tumble
      or rate-table sequence).
    - ``motion``: ``offset_mg`` + sum of sinusoidal tones (vibration, coning) + a Singer
      manoeuvre: a stationary first-order Gauss-Markov acceleration of RMS ``singer_sigma_mg``
      and correlation time ``singer_tau_s``.
    """
    t = np.asarray(t, dtype=np.float64)
    if cfg.kind == "zero":
        return np.zeros_like(t)
    if cfg.kind == "constant":
        return np.full_like(t, cfg.value_mg)
    if cfg.kind == "steps":
        out = np.zeros_like(t)
        if cfg.steps:
            times = np.array([s[0] for s in cfg.steps])
            values = np.array([0.0] + [s[1] for s in cfg.steps])
            out = values[np.searchsorted(times, t, side="right")]
        return out
    if cfg.kind == "motion":
        out = np.full_like(t, cfg.offset_mg)
        for tone in cfg.tones:
            out += tone.amp_mg * np.sin(2.0 * np.pi * tone.freq_hz * t + tone.phase_rad)
        if cfg.singer_sigma_mg > 0 and t.size > 1:
            assert cfg.singer_tau_s is not None, (
                "the configuration requires singer_tau_s with singer_sigma_mg"
            )
            dt = float(t[-1] - t[0]) / (t.size - 1)
            out += gauss_markov(t.size, dt, cfg.singer_tau_s, cfg.singer_sigma_mg, rng)
        return out
    raise ValueError(f"unknown input kind {cfg.kind!r}")
