"""``trainer compare``: train every method on one recording and score them on another.

The methods and their order come from :mod:`trainer.methods`. The paper's three DLSTM methods
(``shares_population``) share their gradient-trained population (stage one of the fusion), exactly
as the paper's comparison does: DLSTM exports the best trained network, DLSTM+SSA and DLSTM+ISSA
refine the same population. PLA, the flight-stack cubic, the temperature-input DLSTM and the
persistence predictor complete the table.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from trainer import methods as registry
from trainer.compensator import Compensator
from trainer.data.channels import channel_unit, relabel_units
from trainer.data.recording import Recording
from trainer.dlstm.fusion import FusionSettings, train_stage
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.fitting import apply_offset_policy
from trainer.reference import OffsetPolicy, recursive_note
from trainer.scoring.evaluate import Evaluation, InputSurvival, evaluate, input_survival
from trainer.scoring.inject import injected_input, input_kept

ORACLE = "oracle"  # evaluation only: accel - true_drift_mg, what perfect compensation would score


@dataclass
class Comparison:
    """Fitted models, their scores, and how long each took to fit."""

    models: dict[str, Compensator]
    fit_seconds: dict[str, float]
    evaluation: Evaluation
    survival: dict[str, dict[str, InputSurvival]] = field(default_factory=dict)  # input rec -> method
    notes: list[str] = field(default_factory=list)  # set-up and warnings for the report


def fit_all(
    train: Recording,
    settings: FusionSettings,
    *,
    methods: tuple[str, ...] | None = None,
    progress: bool = True,
    log: Callable[[str], None] = print,
    policy: OffsetPolicy | None = None,
    jobs: int = 1,
) -> tuple[dict[str, Compensator], dict[str, float]]:
    """Fit every requested method (default: all) on ``train`` (ground truth hidden), in registry order.

    The methods that share the gradient-trained population are fitted first, from one population
    trained once (prepared by the first registered sharing method), then every other method. Every
    temperature-driven model then gets the offset ``policy`` (:mod:`trainer.reference`).
    ``jobs`` > 1: the same fits side by side in that many worker processes, with the same results
    (:mod:`trainer.scoring.side_by_side`).
    """
    train = train.without_truth()
    requested = registry.names() if methods is None else methods
    chosen = [m for m in registry.entries() if m.name in requested]
    models: dict[str, Compensator] = {}
    seconds: dict[str, float] = {}

    def build(method: registry.Method) -> Compensator:
        return method.cls(**method.options.compare_kwargs(settings, progress and jobs == 1))

    if jobs > 1:
        import torch

        from trainer.scoring.side_by_side import fit_side_by_side

        models, seconds = fit_side_by_side(
            train, chosen, build, settings, jobs=jobs, threads=torch.get_num_threads(), log=log
        )
        return _with_policy(models, seconds, chosen, train, policy, log)
    sharing = [m for m in chosen if m.shares_population]
    if sharing:
        log(f"training the DLSTM population ({settings.population} x {settings.iterations} iterations)")
        start = time.perf_counter()
        probe = build(next(m for m in registry.entries() if m.shares_population))
        x, y = probe.prepare(train)  # type: ignore[attr-defined]
        trained = train_stage(x, y, settings, progress=progress)
        shared = time.perf_counter() - start
        for method in sharing:
            log(f"fitting {method.name}")
            start = time.perf_counter()
            models[method.name] = build(method).fit_from_population(train, trained)  # type: ignore[attr-defined]
            seconds[method.name] = shared + time.perf_counter() - start
    for method in chosen:
        if not method.shares_population:
            log(f"fitting {method.name}")
            start = time.perf_counter()
            models[method.name] = build(method).fit(train)
            seconds[method.name] = time.perf_counter() - start
    return _with_policy(models, seconds, chosen, train, policy, log)


def _with_policy(
    models: dict[str, Compensator],
    seconds: dict[str, float],
    chosen: list[registry.Method],
    train: Recording,
    policy: OffsetPolicy | None,
    log: Callable[[str], None],
) -> tuple[dict[str, Compensator], dict[str, float]]:
    """The fitted models in registry order, each with the offset ``policy`` applied."""
    for method in chosen:
        record = apply_offset_policy(models[method.name], method, train, policy or OffsetPolicy())
        log(
            relabel_units(
                f"{method.name}: {record.describe() if record else recursive_note(channel_unit(train))}",
                channel_unit(train),
            )
        )
    return {m.name: models[m.name] for m in chosen}, seconds


def compensate_after(model: Compensator, rec: Recording, lead_in: Recording | None) -> np.ndarray:
    """``model``'s output on ``rec``, its state first run through ``lead_in`` (when given)."""
    if lead_in is None:
        return model.compensate(rec)
    joined = Recording(
        {k: np.concatenate([lead_in.columns[k], v]) for k, v in rec.columns.items() if k in lead_in.columns},
        dict(rec.meta),
        rec.source,
    )
    return model.compensate(joined)[len(lead_in) :]


def compare(
    train: Recording,
    valid: Recording,
    settings: FusionSettings,
    *,
    input_tests: tuple[Recording, ...] = (),
    smoothing_s: float = PAPER_RUN_SMOOTHING_S,
    methods: tuple[str, ...] | None = None,
    progress: bool = True,
    log: Callable[[str], None] = print,
    policy: OffsetPolicy | None = None,
    inject: str | None = None,
    lead_in: Recording | None = None,
    jobs: int = 1,
) -> Comparison:
    """Fit on ``train``, score on ``valid``; ``inject`` (an input preset) is added to ``valid`` to
    measure how much of a known input each method keeps (:mod:`trainer.scoring.inject`).

    ``lead_in``: the samples that precede ``valid`` in the same recording (a held-out end part):
    every method runs through them first and is scored on ``valid`` only, as firmware that has run
    since power-on; without it a method with state (filters, a branch, a network) starts cold.
    ``jobs``: worker processes for the fits (:func:`fit_all`)."""
    models, seconds = fit_all(
        train, settings, methods=methods, progress=progress, log=log, policy=policy, jobs=jobs
    )
    blind = valid.without_truth()
    compensated = {name: compensate_after(model, blind, lead_in) for name, model in models.items()}
    references = {
        name: model.offset.t_ref_c
        for name, model in models.items()
        if model.offset is not None and model.offset.relative
    }
    true_drift = valid.truth("drift_mg")
    if true_drift is not None:
        compensated[ORACLE] = valid.accel_mg - true_drift
    lo, hi = float(np.min(train.temp_c)), float(np.max(train.temp_c))
    outside = (valid.temp_c < lo) | (valid.temp_c > hi)
    evaluation = evaluate(
        valid,
        compensated,
        out_of_range={name: outside for name in models if registry.REGISTRY[name].range_checked},
        smoothing_s=smoothing_s,
        references=references,
    )
    comparison = Comparison(models, seconds, evaluation)
    if inject is not None:
        signal = injected_input(valid, inject)
        comparison.survival[f"injected-{inject}"] = {
            name: input_kept(model, valid, signal) for name, model in models.items()
        }
    for rec in input_tests:
        outputs = {name: model.compensate(rec.without_truth()) for name, model in models.items()}
        if rec.truth("drift_mg") is not None:
            outputs[ORACLE] = rec.accel_mg - rec.truth("drift_mg")
        scores = {}
        for name, output in outputs.items():
            score = input_survival(rec, output)
            if score is not None:
                scores[name] = score
        comparison.survival[rec.source] = scores
    return comparison
