"""Stable selection (issue 21): a finding of a recording survives an identifiable effect added elsewhere.

Synthetic recordings: a chamber cycle with a reversal, a cubic bias, white noise and a small random
walk (seeded), with a hysteresis and a bias step of their own (the "clean" findings), then the same
recording with a periodic component added through the catalogue's formula
(``physics.effects.effect_contribution``).
"""

from __future__ import annotations

from tests.synthetic_chamber import BLOCKS, DURATION_S, chamber_recording
from trainer.data.recording import Recording
from trainer.diagnose import diagnose
from trainer.physics.catalogue import bias_step, hysteresis, periodic

STEP = bias_step.DEFINITION.identifier
HYSTERESIS = hysteresis.DEFINITION.identifier
PERIODIC = periodic.DEFINITION.identifier
OWN = [(HYSTERESIS, {"amp_mg": 0.4, "width_c": 5.0}), (STEP, {"t_s": 1500.0, "step_mg": 1.0})]
ADDED = (PERIODIC, {"amp_mg": 0.5, "period_s": 300.0, "phase_rad": 0.7})


def _findings(rec: Recording) -> list[tuple[str, dict[str, float]]]:
    return [
        (e.effect, dict(e.params)) for e in diagnose(rec, holdout_fraction=0.0, max_blocks=BLOCKS).left_out
    ]


def test_findings_of_a_recording_survive_an_effect_added_elsewhere() -> None:
    """findings(clean) is a subset of findings(clean + periodic): same effects, a step at the same
    time (within two 16 s blocks), and the added periodic is named besides."""
    clean = _findings(chamber_recording(OWN, seed=21))
    assert sorted(e for e, _ in clean) == sorted([HYSTERESIS, STEP])  # the recording's own findings
    added = _findings(chamber_recording([*OWN, ADDED], seed=21))
    for effect, params in clean:
        same = [p for e, p in added if e == effect]
        assert same, f"{effect} of the clean recording is lost: {added}"
        if effect == STEP:
            assert any(abs(p["t_s"] - params["t_s"]) <= 2 * DURATION_S / BLOCKS for p in same)
    periods = [p["period_s"] for e, p in added if e == PERIODIC]
    assert any(abs(1 / p - 1 / ADDED[1]["period_s"]) <= 1 / DURATION_S for p in periods)
