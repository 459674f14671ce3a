"""The selection revisits its choices: no random walk named beside a deterministic effect it mimicked.

Tried as a user would: the user's simulation has the bias polynomial, white noise and bias
instability of the unit but no random walk, and the recording (generated without a random walk
either) hides one deterministic effect. Against the starting model any structured residual looks
like a random walk, so the noise test (run first) accepts one; the stepwise search re-tests it once
the deterministic effect is in and drops it. Before it did, ``rate_random_walk`` was named beside
the hidden effect in every one of these cases.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from trainer.diagnose import diagnose
from trainer.diagnose.document import document
from trainer.diagnose.scenarios import CHECKED_PARAMS, HIDDEN_EFFECTS, make_scenario
from trainer.physics.catalogue import bias_step, hysteresis, rate_random_walk, temp_rate, thermal_lag, warmup
from trainer.physics.config import PhysicsConfig

RANDOM_WALK = rate_random_walk.DEFINITION.identifier
EFFECTS = [m.DEFINITION.identifier for m in (thermal_lag, temp_rate, hysteresis, warmup, bias_step)]
# Seeds by the concealed suite's formula (its second seed per effect), not picked per case.
# The three cheapest in the default run (13-15 s each on the 2-core Xeon VM); the lag and the branch
# offset (29 s, 37 s) behind --runslow, each named with its parameters in test_diagnose_concealed.
DEFAULT_RUN = {temp_rate.DEFINITION.identifier, warmup.DEFINITION.identifier, bias_step.DEFINITION.identifier}
CASES = [
    pytest.param(
        effect,
        301 + 10 * HIDDEN_EFFECTS.index(effect),
        id=f"{effect}-{301 + 10 * HIDDEN_EFFECTS.index(effect)}",
        marks=() if effect in DEFAULT_RUN else (pytest.mark.slow,),
    )
    for effect in EFFECTS
]
TOLERANCE = 0.25


def _without_random_walk(config: PhysicsConfig) -> PhysicsConfig:
    return replace(config, noise=tuple(n for n in config.noise if n.identifier != RANDOM_WALK))


@pytest.mark.parametrize(("effect", "seed"), CASES)
def test_user_sim_without_random_walk_names_only_the_hidden_effect(effect: str, seed: int) -> None:
    scenario = make_scenario([effect], seed, rates=(20.0, 50.0))
    truth = _without_random_walk(scenario.truth)
    sim = _without_random_walk(scenario.sim)
    assert RANDOM_WALK not in {n.identifier for n in (*truth.noise, *sim.noise)}
    scenario = replace(scenario, truth=truth, sim=sim)
    doc: dict[str, Any] = document(diagnose(scenario.recording(), sim, holdout_fraction=0.0))
    names = sorted(e["effect"] for e in doc["left_out"])
    assert names == [effect], f"{scenario.name}: named {names}, concealed only {effect}"
    hidden = scenario.hidden[0]
    entry = doc["left_out"][0]
    for name in CHECKED_PARAMS[effect]:
        true, got = hidden.params[name], entry["params"][name]
        assert abs(got - true) <= TOLERANCE * abs(true), f"{scenario.name}: {name} {got:.4g} vs {true:.4g}"
    # the random walk, accepted against the starting model, is reported as tested and dropped
    dropped = [
        t for t in doc["tested"] if t["effect"] == RANDOM_WALK and t.get("how", "").startswith("dropped")
    ]
    assert dropped and all(t["delta_bic"] < 12.0 for t in dropped), doc["tested"]


def test_a_trend_that_only_replaces_the_random_walk_is_not_named() -> None:
    """Clean draw 3085 (bench_diagnose, offset 2000): its random walk's realisation looks like a
    ramp. Refitting the noise let a rate_ramp replace the walk (walk level to ~0, delta BIC 12.8);
    judged at the walk's own level the ramp gains ~1 and nothing is named."""
    scenario = make_scenario([], 3085, rates=(5.0, 10.0, 20.0, 50.0))
    doc = document(diagnose(scenario.recording(), scenario.sim, holdout_fraction=0.0))
    assert doc["left_out"] == []
