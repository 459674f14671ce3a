"""``--inject steps``: add a known input to the user's own held-out data and see how much survives.

A simulated input test measures input survival on a simulated sensor; a recursive method's
survival depends on the data it runs on (its smoothing, its learned dynamics), so the honest test
uses the user's real recording. The input is one of the simulator's presets
(:mod:`trainer.physics.input_presets`: ``steps`` is a tilt sequence of eight dwells at 0, +20,
-20, +50, 0, -50, +10, 0 mg), stretched over the held-out part and added to ``accel_mg``.

What a method keeps is measured on the *difference* its compensated output shows with and without
the injection, so the drift it leaves on the real data cancels: ``gain`` is the least-squares gain
of that difference on the injected input (1 = kept whole), ``error_rms_mg`` the RMS of difference
minus input (the part of the input removed or distorted).
"""

from __future__ import annotations

import numpy as np

from trainer.compensator import Compensator
from trainer.data.recording import Recording
from trainer.physics.input_presets import INPUT_PRESETS, input_preset
from trainer.physics.inputs import input_signal
from trainer.scoring.evaluate import InputSurvival

INJECT_SEED = 0  # the motion preset draws a random manoeuvre: fixed, so scores are reproducible


def injected_input(rec: Recording, kind: str) -> np.ndarray:
    """The preset input ``kind`` over ``rec``'s duration (mg per sample)."""
    if kind not in INPUT_PRESETS:
        raise ValueError(f"unknown input {kind!r}; choose one of {', '.join(INPUT_PRESETS)}")
    t = rec.time_s - rec.time_s[0]
    return input_signal(input_preset(kind, float(t[-1])), t, np.random.default_rng(INJECT_SEED))


def with_input(rec: Recording, signal: np.ndarray) -> Recording:
    """``rec`` with ``signal`` added to ``accel_mg`` (ground truth hidden)."""
    columns = dict(rec.without_truth().columns)
    columns["accel_mg"] = rec.accel_mg + signal
    return Recording(columns, dict(rec.meta), rec.source)


def input_kept(model: Compensator, rec: Recording, signal: np.ndarray) -> InputSurvival:
    """How much of ``signal``, added to ``rec``, survives ``model``'s compensation."""
    blind = rec.without_truth()
    difference = model.compensate(with_input(blind, signal)) - model.compensate(blind)
    centred = signal - signal.mean()
    gain = float(np.dot(difference - difference.mean(), centred) / np.dot(centred, centred))
    error = difference - signal
    return InputSurvival(gain, float(np.sqrt(np.mean(error**2))), float(np.sqrt(np.mean(centred**2))))
