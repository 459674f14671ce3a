"""The compensator's own test for a term: does it predict blocks it was not fitted on?

The finder judges effects by BIC under its noise model, where a random walk may explain a slow
heating / cooling split as noise. A compensator cannot remove noise, and what matters to it is the
drift it leaves on data it has not seen. So, after the finder, every compensable effect that the
temperature profile identifies (the finder's identifiability rules: a monotone ramp identifies no
lag, rate or hysteresis, and then nothing is tried) is tested by contiguous K-fold cross-validation
on the block means: fitted on the other folds at the profiled nonlinear values (least squares, as
the compensator runs), it must lower the pooled held-out RMS by :data:`MIN_GAIN`.

Cross-validation alone is not enough on one chamber cycle: a random walk of the size real
sensors have splits heating from cooling by chance, and a branch or creep term then predicts the
other folds too (on the finder's clean bench recordings it added a term to 9 of 12). So a term
must also beat the noise model at its current level: the likelihood ratio of the fit with it,
the noise held where the finder fitted it (the random walk may not shrink to make room), must
pass a chi-squared test at :data:`LR_LEVEL` with as many degrees of freedom as the term adds
parameters. Of the terms passing both tests, the one with the lowest held-out RMS is added and
the search repeats.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from scipy.stats import chi2

from trainer.data.channels import UNIT_LABELS
from trainer.diagnose.api import BlockData, ModelFit, Term, build_design
from trainer.greybox.structure import Structure
from trainer.physics.catalogue import excluded
from trainer.physics.catalogue.units import CATALOGUE_UNIT
from trainer.physics.effects import EffectConfig

FOLDS = 5
MIN_GAIN = 0.05  # a term must lower the cross-validated RMS by 5 %
LR_LEVEL = 0.05  # and beat the noise model at its fitted level at this significance
STAGE = "cross-validation"  # how the fit summary's notes name this stage


def beats_noise(trial: ModelFit, current: ModelFit) -> bool:
    """Likelihood-ratio test of ``trial`` against ``current`` at ``current``'s noise."""
    added = max(trial.n_params - current.n_params, 1)
    return 2.0 * (trial.loglik - current.loglik) > float(chi2.isf(LR_LEVEL, added))


def cv_rms(terms: tuple[Term, ...], data: BlockData, folds: int = FOLDS) -> float:
    """Pooled RMS (mean removed) of each contiguous fold predicted by least squares on the others.

    Blocks without weight (``data.held_out``: a segment an outer cross-validation holds out, its
    output imputed by the cubic) neither train nor score: a term would otherwise be judged on how
    well it predicts the cubic."""
    design = build_design(terms, data)
    y = data.accel - design.offset
    X = design.X
    counted = np.ones(data.n, dtype=bool) if data.held_out is None else ~data.held_out
    edges = np.linspace(0, data.n, folds + 1).astype(int)
    residual = np.empty(data.n)
    for k in range(folds):
        test = np.zeros(data.n, dtype=bool)
        test[edges[k] : edges[k + 1]] = True
        beta, *_ = np.linalg.lstsq(X[~test & counted], y[~test & counted], rcond=None)
        residual[test] = y[test] - X[test] @ beta
    residual = residual[counted]
    residual -= residual.mean()
    return float(np.sqrt(np.mean(residual**2)))


def extend(
    fit: ModelFit,
    data: BlockData,
    structure: Structure,
    add: Callable[[ModelFit, BlockData, EffectConfig], ModelFit | None],
    *,
    unit: str = CATALOGUE_UNIT,
    undetermined: Callable[[ModelFit, str], str] | None = None,
) -> tuple[ModelFit, Structure, list[str]]:
    """Add candidates while one lowers the cross-validated RMS by ``MIN_GAIN`` and beats the noise.

    ``add(fit, data, effect)`` places one effect (the finder's profile search; ``None`` where it
    places it nowhere: that candidate is noted and dropped); returns the
    extended fit, the structure with the accepted effects, and one note per decision (figures in
    the channel's unit, ``unit`` its suffix). ``undetermined(trial, effect)``: why the run does not
    determine the placed term ("" when it does); such a trial is not chosen (the fit would drop it),
    so that a determined one (a rate term beside a creep at the end of its range) can be.
    """
    label = UNIT_LABELS[unit]
    notes: list[str] = []
    current = cv_rms(fit.terms, data)
    remaining = list(structure.candidates)
    accepted: list[EffectConfig] = []
    while remaining:
        # a later round judges each candidate again, beside the terms added so far: say so, or two
        # rounds read as two contradicting figures for one term
        stage = STAGE + (f" (beside {', '.join(e.identifier for e in accepted)})" if accepted else "")
        trials = []
        for name in list(remaining):
            if any(excluded(name, t.identifier) for t in fit.terms):
                continue
            trial = add(fit, data, EffectConfig(name, {}))
            if trial is None:
                notes.append(f"{stage}: {name} not tried: the finder places it nowhere on these rows")
                remaining.remove(name)
                continue
            trials.append((cv_rms(trial.terms, data), name, trial))
        if not trials:
            break
        passing = [item for item in trials if beats_noise(item[2], fit)]
        set_aside: set[str] = set()  # beat the noise, but the run does not determine them
        if undetermined is not None:
            why = {name: undetermined(trial, name) for _, name, trial in passing}
            notes += [f"{stage}: {name} not added, undetermined: {w}" for name, w in why.items() if w]
            set_aside = {name for name, w in why.items() if w}
            passing = [item for item in passing if item[1] not in set_aside]
        if not passing:
            best = min(trials, key=lambda item: item[0])
            which = "term this run determines" if set_aside else "term"
            aside = ", undetermined: not added (above)" if best[1] in set_aside else ""
            notes.append(
                f"{stage}: no further {which} beats the noise model at p < {LR_LEVEL:g} "
                f"(best held out: {best[1]}, {current:.4g} -> {best[0]:.4g} {label}{aside})"
            )
            break
        score, name, trial = min(passing, key=lambda item: item[0])
        if score > (1.0 - MIN_GAIN) * current:
            notes.append(
                f"{stage}: no further term lowers the held-out block RMS by {MIN_GAIN:.0%} "
                f"(best: {name}, {current:.4g} -> {score:.4g} {label})"
            )
            break
        notes.append(f"{stage}: {name} lowers the held-out block RMS {current:.4g} -> {score:.4g} {label}")
        fit, current = trial, score
        accepted.append(EffectConfig(name, {}))
        remaining.remove(name)
    if accepted:
        structure = replace(structure, compensated=(*structure.compensated, *accepted))
    return fit, structure, notes
