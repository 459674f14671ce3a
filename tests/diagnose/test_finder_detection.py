"""Detection limits (issue 21, item 3): a weakly identifiable effect that is not named is reported
with the smallest size this run names, instead of silence.

The stated limit re-estimates the noise as the finder does; on a quiet run (no random walk) a step
the model leaves out raises the estimated random walk, and the closed form at the clean run's noise
was 2 to 3 times too small: a step at twice it was not named.

A generated chamber run that starts on a ramp (no soak at power-on: a warm-up is only weakly
identifiable there). The closed-form limit is checked against the finder's own BIC (``evaluate``,
``count_params``): data built to hold the effect at exactly the limit make the BIC drop exactly by
the threshold. Then the finder itself: a warm-up well below the limit is not named and is reported
with a limit above its size; one well above is named.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.synthetic_chamber import BLOCKS, DURATION_S, chamber_recording
from trainer.diagnose import Diagnosis, detection, diagnose
from trainer.diagnose.detection import DetectionLimit, evidence_beside, limit_at, shape_content, shape_limit
from trainer.diagnose.document import undetected
from trainer.diagnose.model import ModelFit, Term, build_design, evaluate, fit_model
from trainer.diagnose.report import limit_sizes, markdown
from trainer.diagnose.select import THRESHOLD
from trainer.diagnose.shared import shared_signatures, shared_text
from trainer.physics.catalogue import bias_step, warmup

WARMUP = warmup.DEFINITION.identifier
STEP = bias_step.DEFINITION.identifier
TAU_S = 400.0


def ramp_start(t: np.ndarray) -> np.ndarray:
    """50 -> -10 degC from power-on (no soak), back up to 60 degC, down to 30 degC."""
    return np.interp(t, [0.0, 1500.0, 3300.0, DURATION_S], [50.0, -10.0, 60.0, 30.0])


@pytest.fixture(scope="module")
def clean() -> Diagnosis:
    return diagnose(
        chamber_recording([], seed=31, temperature_c=ramp_start), holdout_fraction=0.0, max_blocks=BLOCKS
    )


def test_limit_is_where_the_criterion_names_the_effect(clean: Diagnosis) -> None:
    """Block means = the model's prediction + its residual made orthogonal to the warm-up column (its
    norm kept) +
    the warm-up at the stated limit: the model with the warm-up (its time constant held, charged as
    the search charges it) is better by exactly the threshold."""
    fit = clean.selection.final
    data = fit.data
    limit = limit_at(fit, WARMUP, TAU_S, closed_form=True)
    terms = [*fit.terms, Term(WARMUP, (TAU_S,))]
    design = build_design(terms, data)
    own = np.array([owner == len(terms) - 1 for owner, _ in design.roles])
    column = design.X[:, own][:, 0]
    # the residual, whitened, without its component along the whitened column beyond the model's
    white_residual = fit.gls.whiten(fit.residual)
    white_others = fit.gls.whiten(design.X[:, ~own])
    white_column = fit.gls.whiten(column)
    beta, *_ = np.linalg.lstsq(white_others, white_column, rcond=None)
    direction = white_column - white_others @ beta
    rss = float(white_residual @ white_residual)
    white_residual = white_residual - direction * float(direction @ white_residual) / float(
        direction @ direction
    )
    white_residual *= np.sqrt(rss / float(white_residual @ white_residual))  # the model's rss kept
    residual = fit.gls.chol @ white_residual
    accel = fit.prediction + residual + limit.amplitude * column
    shifted = replace(data, accel=accel)
    without = evaluate(list(fit.terms), shifted, fit.gls)
    with_it = evaluate(terms, shifted, fit.gls)
    assert without.bic - with_it.bic == pytest.approx(THRESHOLD, abs=1e-6)
    assert 0.0 <= limit.absorbed <= 1.0


def test_a_warmup_below_the_limit_is_said_and_one_above_is_named(clean: Diagnosis) -> None:
    limit = limit_at(clean.selection.final, WARMUP, TAU_S).amplitude
    assert [u.effect for u in clean.undetected].count(WARMUP) == 1  # weak, not named, reported
    small = 0.4 * limit
    rec = chamber_recording([(WARMUP, {"amp_mg": small, "tau_s": TAU_S})], seed=31, temperature_c=ramp_start)
    d = diagnose(rec, holdout_fraction=0.0, max_blocks=BLOCKS)
    assert WARMUP not in [e.effect for e in d.left_out]
    said = [u for u in d.undetected if u.effect == WARMUP]
    assert said and limit_at(d.selection.final, WARMUP, TAU_S).amplitude > small
    assert "smallest size this run names" in markdown(d) and "- warmup:" in markdown(d)
    large = 3.5 * limit  # well above it, below the plausible 5 mg
    rec = chamber_recording([(WARMUP, {"amp_mg": large, "tau_s": TAU_S})], seed=31, temperature_c=ramp_start)
    d = diagnose(rec, holdout_fraction=0.0, max_blocks=BLOCKS)
    named = [e.params for e in d.left_out if e.effect == WARMUP]
    assert named and named[0]["amp_mg"] == pytest.approx(large, rel=0.25)
    assert WARMUP not in [u.effect for u in d.undetected]


def test_an_instance_shape_has_the_limit_of_its_effect(clean: Diagnosis) -> None:
    """The limit of a warm-up's own full-rate shape (block means taken here) is the effect's limit at
    its time constant (the finder's exact block-mean column): one criterion, two ways in."""
    fit = clean.selection.final
    t = fit.data.full_t
    shaped = shape_limit(fit, WARMUP, np.exp(-t / TAU_S), (TAU_S,), closed_form=True)
    assert shaped.amplitude == pytest.approx(
        limit_at(fit, WARMUP, TAU_S, closed_form=True).amplitude, rel=0.01
    )


def test_a_shape_content_is_its_coefficient_beside_the_model(clean: Diagnosis) -> None:
    """The run's own amplitude of a warm-up shape (what the bench scores an added instance against,
    beside the added size) is the warm-up's GLS coefficient when the model is refitted with it at the
    same noise; adding ``a`` of the shape to the data adds exactly ``a``."""
    fit = clean.selection.final
    data = fit.data
    shape = np.exp(-data.full_t / TAU_S)
    amplitude, error = shape_content(fit, WARMUP, shape, (TAU_S,))
    terms = [*fit.terms, Term(WARMUP, (TAU_S,))]
    with_it = evaluate(terms, data, fit.gls)
    (index,) = [k for k, (owner, _) in enumerate(with_it.roles) if owner == len(terms) - 1]
    assert amplitude == pytest.approx(float(with_it.beta[index]), rel=1e-6, abs=1e-9)
    assert 0.0 < error < limit_at(fit, WARMUP, TAU_S).amplitude
    design = build_design(terms, data)
    column = design.X[:, [owner == len(terms) - 1 for owner, _ in design.roles]][:, 0]
    shifted = replace(data, accel=data.accel + 0.3 * column)
    refit = evaluate(list(fit.terms), shifted, fit.gls)
    assert shape_content(refit, WARMUP, shape, (TAU_S,))[0] == pytest.approx(amplitude + 0.3, rel=1e-6)


QUIET_STEP_S = 0.55 * DURATION_S


def quiet_run(step_mg: float) -> Diagnosis:
    """A white-noise-only run (the random walk at its lower bound), with a step at QUIET_STEP_S."""
    effects = [(STEP, {"t_s": QUIET_STEP_S, "step_mg": step_mg})] if step_mg else []
    return diagnose(chamber_recording(effects, seed=32, walk_mg=0.0), holdout_fraction=0.0, max_blocks=BLOCKS)


@pytest.fixture(scope="module")
def quiet() -> Diagnosis:
    return quiet_run(0.0)


def test_a_step_on_a_quiet_run_is_named_from_its_stated_limit_on(quiet: Diagnosis) -> None:
    """The stated limit of a step is above the closed form, and the finder itself draws the line
    there: a step at half the limit is not named, one at twice the closed form (below the limit) is
    not named either, one at twice the limit is named at its size."""
    fit = quiet.selection.final
    shape = (fit.data.full_t >= QUIET_STEP_S).astype(float)
    limit = shape_limit(fit, STEP, shape, (QUIET_STEP_S,)).amplitude
    closed = shape_limit(fit, STEP, shape, (QUIET_STEP_S,), closed_form=True).amplitude
    assert limit > 2.0 * closed
    for below in (0.5 * limit, 2.0 * closed):
        assert STEP not in [e.effect for e in quiet_run(below).left_out]
    named = [e.params for e in quiet_run(2.0 * limit).left_out if e.effect == STEP]
    assert len(named) == 1 and named[0]["step_mg"] == pytest.approx(2.0 * limit, rel=0.25)


def test_a_limit_beyond_the_search_is_a_lower_bound_and_said_so(
    quiet: Diagnosis, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Searched only up to 1.5 times the closed form (the step needs about 3): the limit returned is
    the largest size tried, flagged a lower bound, printed ``> x`` and ``at_least`` in the JSON."""
    monkeypatch.setattr(detection, "REFIT_MAX_FACTOR", 1.5)
    fit = quiet.selection.final
    shape = (fit.data.full_t >= QUIET_STEP_S).astype(float)
    closed = shape_limit(fit, STEP, shape, (QUIET_STEP_S,), closed_form=True)
    bound = shape_limit(fit, STEP, shape, (QUIET_STEP_S,))
    assert bound.at_least and not closed.at_least
    assert bound.amplitude == pytest.approx(2.0 * closed.amplitude)
    said = DetectionLimit(STEP, "t_s", "step_mg", (0.0, 10.0), (bound,), "a reason", "a test")
    assert limit_sizes(said).startswith("> ")
    assert undetected(said)["smallest_named"][0]["at_least"] is True


STEP_AT_S = 3500.0


@pytest.fixture(scope="module")
def stepped() -> Diagnosis:
    recording = chamber_recording([(STEP, {"t_s": STEP_AT_S, "step_mg": 0.6})], seed=41)
    return diagnose(recording, holdout_fraction=0.0, max_blocks=BLOCKS)


def test_a_finding_earns_nothing_beside_its_own_signature(stepped: Diagnosis) -> None:
    """``evidence_beside``: the BIC drop a named step earns with other terms in the model. Beside a
    held step at its own time (the same column) it adds nothing and costs its parameters, at most
    ``(1 + 2) ln n`` (an amplitude, a scanned time charged twice; its own time is still free to fit
    a little noise): below zero. Beside a held step far away it keeps the criterion."""
    fit = stepped.selection.final
    index = next(k for k, t in enumerate(fit.terms) if t.identifier == STEP)
    found_at_s = fit.terms[index].nl[0]
    assert abs(found_at_s - STEP_AT_S) <= 2 * fit.data.block_s
    same = evidence_beside(fit, index, [Term(STEP, (found_at_s,), fixed=True)])
    assert -3.0 * np.log(fit.data.n) - 0.5 <= same < 0.0
    far = evidence_beside(fit, index, [Term(STEP, (1000.0,), fixed=True)])
    assert far >= THRESHOLD


def test_a_near_miss_names_the_effect_it_shares_its_signature_with(stepped: Diagnosis) -> None:
    """``shared_signatures``: a second step held at the named step's instant earns nothing beside the
    final model (the same column), but the criterion once the named step is out of the model, so the
    named step is the effect it shares its signature with; in its place the model is the same one (the
    BIC within the named step's freedom to move its time by noise). A held step at 1000 s, where the
    run has none, shares nothing: it earns nothing without the named step either."""
    fit = stepped.selection.final
    index = next(k for k, t in enumerate(fit.terms) if t.identifier == STEP)
    own_s = fit.terms[index].nl[0]

    def miss_fit(t_s: float) -> ModelFit:
        return fit_model(
            (*fit.terms, Term(STEP, (t_s,), fixed=True)), fit.noise.terms, fit.data, start=fit.noise
        )

    (shared,) = shared_signatures(fit, miss_fit(own_s))
    assert shared.effect == STEP
    assert shared.delta_bic >= THRESHOLD
    assert abs(shared.in_place_bic) <= 2.0 * np.log(fit.data.n)
    text = shared_text((shared,))
    assert f"shares its signature with {STEP}" in text and f"{shared.delta_bic:.1f}" in text
    assert shared_signatures(fit, miss_fit(1000.0)) == ()
