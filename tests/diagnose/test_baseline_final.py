"""``baseline_final``: the user's effects as the final model fitted them beside what the finder
named. Calibrated alone, a bias polynomial bends to hold a step it cannot (``baseline_calibrated``),
and ``trainer fleet`` flagged a step unit's temperature coefficients as out of family."""

from __future__ import annotations

from dataclasses import replace

from trainer.data.recording import Recording
from trainer.diagnose import diagnose
from trainer.diagnose.document import document
from trainer.physics.catalogue import bias_step
from trainer.physics.config import load_config, with_overrides
from trainer.physics.effects import EffectConfig
from trainer.physics.simulate import simulate

STEP = bias_step.DEFINITION.identifier


def _step_run() -> Recording:
    """The default sensor (trainer/physics/default.toml) through the extended profile in 3000 s at
    5 Hz, with a 0.5 mg bias step at 1000 s (seed 9: the polynomial calibrated alone bends 8 %)."""
    cfg = with_overrides(load_config(), protocol="extended", duration_s=3000.0, sample_rate_hz=5.0)
    cfg = replace(cfg, effects=(*cfg.effects, EffectConfig(STEP, {"t_s": 1000.0, "step_mg": 0.5})))
    return simulate(cfg, seed=9)


def test_the_final_polynomial_is_the_one_the_step_did_not_bend() -> None:
    """At the fleet's block count (200: the bent polynomial flagged a fleet unit's c0..c3)."""
    true_c1 = load_config().effect_instances("bias_poly")[0].params["c1_mg_per_c"]
    doc = document(diagnose(_step_run(), None, max_blocks=200))
    assert [e["effect"] for e in doc["left_out"]] == [STEP]
    final = doc["baseline_final"]["bias_poly"]["c1_mg_per_c"]
    alone = doc["baseline_calibrated"]["bias_poly"]["c1_mg_per_c"]
    assert abs(final - true_c1) < 0.2 * abs(alone - true_c1)
    assert set(doc["baseline_final"]) == set(doc["baseline_calibrated"])
