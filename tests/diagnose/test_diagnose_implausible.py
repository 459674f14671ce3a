"""An implausible best fit is reported as ambiguous, not named; the terminal summary and report."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import pytest

from trainer.commands.diagnose_cmd import summary
from trainer.diagnose import diagnose
from trainer.diagnose.document import document
from trainer.diagnose.report import markdown
from trainer.diagnose.result import Diagnosis
from trainer.diagnose.scenarios import make_scenario
from trainer.physics.catalogue.stress_relaxation import DEFINITION as CREEP
from trainer.physics.effects import EffectConfig

_PLAUSIBLE = CREEP.params[0].plausible
assert _PLAUSIBLE is not None
GAIN = 10.0 * _PLAUSIBLE[1]  # ten times the largest plausible creep gain


@pytest.fixture(scope="module")
def huge_creep() -> Diagnosis:
    """A concealed package creep with a gain far outside the catalogue's plausible range."""
    scenario = make_scenario([CREEP.identifier], 811, rates=(2.0,))
    effects = tuple(
        EffectConfig(e.identifier, {**e.params, "gain_mg_per_c": GAIN})
        if e.identifier == CREEP.identifier
        else e
        for e in scenario.truth.effects
    )
    rec = replace(scenario, truth=replace(scenario.truth, effects=effects)).recording()
    return diagnose(rec, scenario.sim)


def test_implausible_best_fit_is_ambiguous_not_named(huge_creep: Diagnosis) -> None:
    d = huge_creep
    assert all(not e.flags for e in d.left_out if e.peak_visible_mg is not None)
    assert CREEP.identifier not in [e.effect for e in d.left_out]
    entry = next(a for a in d.ambiguous if a.implausible is not None)
    assert entry.effects[0] == CREEP.identifier and entry.implausible is not None
    assert entry.implausible.flags and entry.alternatives
    assert any(len(alt.effects) == 2 for alt in entry.alternatives)  # pairs were tried too
    doc = document(d)
    item = next(a for a in doc["ambiguous"] if "best_fit" in a)
    assert item["best_fit"]["effect"] == CREEP.identifier and item["best_fit"]["flags"]
    assert {"delta_bic", "effects", "flags"} <= set(item["alternatives"][0])


def test_summary_and_report(huge_creep: Diagnosis) -> None:
    text = summary(huge_creep)
    assert "ambiguous (not named)" in text and CREEP.identifier in text
    assert sum("held-out" in line for line in text.splitlines()) <= 1
    assert "least squares, bare" not in text and "GLS" not in text
    assert "next: physics compensator" in text and "residual per branch" in text
    report = markdown(huge_creep)
    assert report.rstrip().split("## ")[-1].startswith("What to do next")
    assert "as fitted (GLS" not in report and "| heating |" in report


@pytest.mark.slow  # about 20 s alone, up to 45 s on a busy machine
def test_real_run_names_no_implausible_effect(real_run: Path) -> None:
    from trainer.data.importer import import_foreign, options_with_preset

    started = time.perf_counter()
    d = diagnose(import_foreign(real_run, options_with_preset("tofupilot")))
    assert time.perf_counter() - started < 120.0
    assert all(not e.flags for e in d.left_out if e.peak_visible_mg is not None)
    assert any(a.implausible is not None for a in d.ambiguous)
    text = summary(d)
    assert "weakly identifiable: " in text and "ambiguous (not named)" in text
    assert "least squares, bare" not in text
