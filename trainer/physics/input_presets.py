"""Built-in true-input profiles (``trainer simulate --input NAME``) for the input-survival test.

A compensator that learns from the past output (the paper's recursive model) also removes a real
acceleration; these inputs measure how much of it survives. Both scale with the recording's
duration so that short test recordings get the same pattern.

- ``steps``: a tilt sequence of a static fixture, eight equal dwell periods at
  0, +20, -20, +50, 0, -50, +10, 0 mg (small tilts around level, as a rate table would give);
- ``motion``: vehicle-like manoeuvres: a Singer process of 20 mg RMS with a 30 s correlation time
  plus a 5 mg, 2 Hz vibration tone.
"""

from __future__ import annotations

from trainer.physics.config import InputConfig, Tone

STEP_LEVELS_MG = (0.0, 20.0, -20.0, 50.0, 0.0, -50.0, 10.0, 0.0)
INPUT_PRESETS = ("steps", "motion")


def input_preset(name: str, duration_s: float) -> InputConfig:
    """The :class:`InputConfig` of preset ``name`` for a recording of ``duration_s`` seconds."""
    if name == "steps":
        dwell = duration_s / len(STEP_LEVELS_MG)
        steps = tuple((round(k * dwell, 6), level) for k, level in enumerate(STEP_LEVELS_MG))
        return InputConfig(kind="steps", steps=steps)
    if name == "motion":
        return InputConfig(kind="motion", singer_sigma_mg=20.0, singer_tau_s=30.0, tones=(Tone(5.0, 2.0),))
    raise ValueError(f"unknown input preset {name!r}; choose one of {', '.join(INPUT_PRESETS)}")
