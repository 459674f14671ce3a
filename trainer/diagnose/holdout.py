"""The held-out check: fit both models on the leading part of the run, score them on the tail."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trainer.diagnose.blocks import BlockData
from trainer.diagnose.fit_summary import rms
from trainer.diagnose.gls import unit_matrices
from trainer.diagnose.model import ModelFit, Term, build_design, fit_model
from trainer.physics.catalogue import DEFINITIONS

# The one held-out figure shown (terminal, report summary) is the least-squares refit extrapolated
# bare (``test_rms_block_mg_ols``): it is what a calibration (cubic or physics compensator) does in
# the field, with no noise model at run time. The GLS forecast adds the noise model's conditional
# mean (BLUP) of the tail given the fitting part's residual, so it scores the noise model as much
# as the effects, and the two figures can disagree; the JSON keeps both.
HEADLINE = "test_rms_block_mg_ols"
MIN_TRAIN_BLOCKS = 120  # fewer blocks than this to fit on: no check
MIN_TEST_BLOCKS = 20  # fewer held-out blocks than this to score on: no check


@dataclass(frozen=True)
class HoldoutScore:
    """One model's block RMS (mg) on the held-out tail and, least-squares refit, on the fitting part."""

    test_rms_block_mg: float  # as fitted (GLS), the forecast is regression plus noise BLUP
    test_rms_block_mg_ols: float  # the same terms refitted by least squares, extrapolated bare
    train_rms_block_mg_ols: float


@dataclass(frozen=True)
class Holdout:
    """Both models fitted on ``0..train_t_end_s`` and scored on ``test_t_start_s..test_t_end_s``."""

    train_t_end_s: float
    test_t_start_s: float
    test_t_end_s: float
    before: HoldoutScore
    after: HoldoutScore
    note: str = ""

    @property
    def improvement_percent(self) -> float | None:
        return _improvement(self.before.test_rms_block_mg, self.after.test_rms_block_mg)

    @property
    def improvement_percent_ols(self) -> float | None:
        return _improvement(self.before.test_rms_block_mg_ols, self.after.test_rms_block_mg_ols)


def _improvement(before: float, after: float) -> float | None:
    return 100.0 * (before - after) / before if before > 0 else None


def predict(fit: ModelFit, data: BlockData) -> np.ndarray:
    """``fit``'s terms and coefficients evaluated on (possibly longer) ``data``, matching columns by role.

    Columns that the fitting data did not have (a quantised hold that only starts later) get 0.
    """
    design = build_design(fit.terms, data)
    coef = dict(zip(fit.roles, fit.beta, strict=True))
    beta = np.array([coef.get(role, 0.0) for role in design.roles])
    return design.X @ beta + design.offset


def noise_forecast(fit: ModelFit, data: BlockData, n_train: int, residual_train: np.ndarray) -> np.ndarray:
    """Conditional mean of the modelled noise over blocks ``n_train:`` given the training residual.

    With flicker and a random walk in the noise model, the best forecast of a held-out stretch is
    the regression plus this kriging term (the BLUP); with white noise only it is zero.
    """
    if not fit.noise.terms:
        return np.zeros(data.n - n_train)
    units = unit_matrices(data.n, data.block_s, data.duration_s)
    cov = np.eye(data.n)
    for term, ratio in fit.noise.ratios().items():
        cov += ratio * units[term]
    weights = np.linalg.solve(cov[:n_train, :n_train], residual_train)
    return cov[n_train:, :n_train] @ weights


def holdout_check(
    baseline_fit: ModelFit, final: ModelFit, data: BlockData, fraction: float
) -> Holdout | None:
    """Fit both models on the leading part of the run and score them on the held-out tail.

    Two scores: the models as fitted (GLS, the held-out forecast is the regression plus the
    noise model's conditional mean, the BLUP) and the same terms refitted by ordinary least
    squares and extrapolated bare, which is what a compensator without noise model would do.
    """
    n_train = round((1.0 - fraction) * data.n)
    if n_train < MIN_TRAIN_BLOCKS or data.n - n_train < MIN_TEST_BLOCKS:
        return None
    train = data.subset(n_train)
    cut = float(data.starts[n_train])

    def after_cut(t: Term) -> bool:  # an event (a step) inside the held-out part
        return DEFINITIONS[t.identifier].finder.event_time and t.nl[0] >= cut - data.block_s

    def learnable(fit: ModelFit) -> list[Term]:
        return [t for t in fit.terms if not after_cut(t)]

    note = ""
    unlearnable = dict.fromkeys(t.identifier for t in final.terms if after_cut(t))
    if unlearnable:
        note = (
            f"a {' or '.join(unlearnable)} inside the held-out part cannot be learned from the fitting part; "
            "left out of both"
        )
    scores = []
    for fit in (baseline_fit, final):
        terms = learnable(fit)
        refit = fit_model(terms, fit.noise.terms, train, start=fit.noise)
        residual = data.accel - predict(refit, data)
        forecast = noise_forecast(refit, data, n_train, residual[:n_train])
        ols = fit_model(terms, (), train)
        residual_ols = data.accel - predict(ols, data)
        scores.append(
            HoldoutScore(
                test_rms_block_mg=rms(residual[n_train:] - forecast),
                test_rms_block_mg_ols=rms(residual_ols[n_train:]),
                train_rms_block_mg_ols=rms(residual_ols[:n_train]),
            )
        )
    worse = worse_note(scores[0], scores[1], data, n_train)
    return Holdout(cut, cut, data.duration_s, scores[0], scores[1], "; ".join(x for x in (note, worse) if x))


WORSE_MARGIN = 1.05  # the found terms leave 5 % more on the tail than the starting model: said


def worse_note(before: HoldoutScore, after: HoldoutScore, data: BlockData, n_train: int) -> str:
    """Said when the found terms, fitted on the leading part, leave more on the tail than the starting
    model: what they fit does not carry over (a compensator built from them would not either), with
    the share of the tail outside the leading part's temperature range, where every term extrapolates."""
    if not after.test_rms_block_mg_ols > WORSE_MARGIN * before.test_rms_block_mg_ols:
        return ""
    temp = data.temperature(False)
    lo, hi = float(np.min(temp[:n_train])), float(np.max(temp[:n_train]))
    outside = float(np.mean((temp[n_train:] < lo) | (temp[n_train:] > hi)))
    where = (
        f"; {100 * outside:.0f} % of the tail lies outside the leading part's {lo:.1f} .. {hi:.1f} degC"
        if outside > 0
        else ""
    )
    return (
        "the found terms leave more on the tail than the starting model: fitted on the leading part they do "
        f"not carry over{where}"
    )
