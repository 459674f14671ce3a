"""``baseline_final``: the user's effects as the final model fitted them beside what the finder
named. Calibrated alone, a bias polynomial bends to hold a step it cannot (``baseline_calibrated``),
and ``trainer fleet`` flagged a step unit's temperature coefficients as out of family."""

from __future__ import annotations

from trainer.diagnose import diagnose
from trainer.diagnose.document import document
from trainer.physics.config import parse_config_text
from trainer.physics.simulate import simulate

TRUE_C1_MG_PER_C = 0.12
SIM = f"""
[recording]
sample_rate_hz = 5.0
duration_s = 3000.0
[protocol]
name = "extended"
[temperature]
case_tau_s = 180.0
temp_noise_c = 0.03
[input]
kind = "zero"
[effects.bias_poly]
c0_mg = 0.5
c1_mg_per_c = {TRUE_C1_MG_PER_C}
c2_mg_per_c2 = 0.0008
c3_mg_per_c3 = 4e-6
[effects.bias_step]
t_s = 1000.0
step_mg = 0.5
[noise.white_noise]
n_mg_rt_s = 0.025
[noise.bias_instability]
b_mg = 0.02
[noise.rate_random_walk]
k_mg_per_rt_s = 0.0005
"""


def test_the_final_polynomial_is_the_one_the_step_did_not_bend() -> None:
    """At the fleet's block count (200: the bent polynomial flagged a fleet unit's c0..c3)."""
    result = diagnose(simulate(parse_config_text(SIM), seed=9), None, max_blocks=200)
    doc = document(result)
    assert [e["effect"] for e in doc["left_out"]] == ["bias_step"]
    final = doc["baseline_final"]["bias_poly"]["c1_mg_per_c"]
    alone = doc["baseline_calibrated"]["bias_poly"]["c1_mg_per_c"]
    assert abs(final - TRUE_C1_MG_PER_C) < 0.2 * abs(alone - TRUE_C1_MG_PER_C)
    assert set(doc["baseline_final"]) == set(doc["baseline_calibrated"])
