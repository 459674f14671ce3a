"""A confounder the run cannot determine, but which would move a named value, is said.

A concealed thermal lag, rate term and hysteresis on a generated chamber run (seed 2 of
``make_scenario``): the rate term earns too little both in the lag's place and beside the model, so
it is neither named nor absorbed, and the hysteresis named beside the lag comes out about three
times its true amplitude (on ramps at one rate a rate term is a branch offset). Nothing was said.
Fitted beside the model, the rate term moves that amplitude by more than the finder's 25 %: the
terminal, the report and the JSON now list it as undetermined, with both values.
"""

from __future__ import annotations

import pytest

from trainer.commands.diagnose_cmd import summary
from trainer.diagnose import diagnose
from trainer.diagnose.document import document
from trainer.diagnose.report import markdown
from trainer.diagnose.result import Diagnosis
from trainer.diagnose.scenarios import make_scenario
from trainer.diagnose.select import AMBIGUOUS, MOVED_FRACTION, THRESHOLD
from trainer.physics.catalogue import hysteresis, temp_rate, thermal_lag

LAG, RATE, LOOP = (m.DEFINITION.identifier for m in (thermal_lag, temp_rate, hysteresis))


@pytest.fixture(scope="module")
def concealed() -> tuple[Diagnosis, dict[str, dict[str, float]]]:
    scenario = make_scenario([LAG, RATE, LOOP], 2)
    truth = {e.identifier: dict(e.params) for e in scenario.truth.effects}
    return diagnose(scenario.recording(), scenario.sim, report_search=False), truth


def test_an_undetermined_rate_term_that_moves_the_hysteresis_is_said_with_both_values(
    concealed: tuple[Diagnosis, dict[str, dict[str, float]]],
) -> None:
    d, truth = concealed
    named = {e.effect: e.params for e in d.left_out}
    assert LOOP in named and RATE not in named
    assert not any(a.absorbed and RATE in a.effects for a in d.ambiguous)
    true_amp, named_amp = truth[LOOP]["amp_mg"], named[LOOP]["amp_mg"]
    assert abs(named_amp - true_amp) > MOVED_FRACTION * abs(true_amp)  # why it must be said
    entry = next(a for a in d.ambiguous if a.undetermined)
    assert entry.effects == (LOOP, RATE)
    # the run cannot tell one from none: it earns less than the criterion and costs less than a tie
    assert -THRESHOLD < entry.delta_bic < AMBIGUOUS
    moved = {(effect, name): (value, beside) for effect, name, value, beside in entry.moves}
    value, beside = moved[(LOOP, "amp_mg")]
    assert value == named_amp and abs(beside - value) > MOVED_FRACTION * abs(value)
    # fitted beside, the amplitude moves towards the concealed one
    assert abs(beside - true_amp) < abs(value - true_amp)
    text = f"{LOOP}.amp_mg {value:.4g} -> {beside:.4g}"
    line = next(
        line for line in summary(d).splitlines() if line.startswith(f"undetermined: {RATE} beside {LOOP}")
    )
    assert text in line
    assert text in markdown(d)
    doc = next(a for a in document(d)["ambiguous"] if a.get("undetermined"))
    assert doc["effects"] == [LOOP, RATE] and "absorbed" not in doc
    assert {"effect": LOOP, "param": "amp_mg", "value": value, "value_beside": beside} in doc["moves_beside"]


def test_an_undetermined_confounder_is_no_alternative_for_the_compensator(
    concealed: tuple[Diagnosis, dict[str, dict[str, float]]],
) -> None:
    d, _ = concealed
    loop = next(e for e in d.left_out if e.effect == LOOP)
    assert RATE not in loop.ambiguous_with
    structure = next(line for line in summary(d).splitlines() if line.startswith("next: physics compensator"))
    assert RATE not in structure
