"""``trainer compare``: train every method on one recording and score them on another.

The paper's three DLSTM methods share their gradient-trained population (stage one of the
fusion), exactly as the paper's comparison does: DLSTM exports the best trained network, DLSTM+SSA
and DLSTM+ISSA refine the same population. PLA, the flight-stack cubic, the temperature-input
DLSTM and the persistence predictor complete the table.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from trainer.baselines.pla import PiecewiseLinear
from trainer.baselines.poly3 import CubicPolynomial
from trainer.compensator import Compensator
from trainer.data.recording import Recording
from trainer.dlstm.compensators import (
    Persistence,
    RecursiveDLSTM,
    RecursiveDLSTMWithISSA,
    RecursiveDLSTMWithSSA,
    TemperatureDLSTM,
)
from trainer.dlstm.fusion import FusionSettings, train_stage
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.scoring.evaluate import Evaluation, InputSurvival, evaluate, input_survival

ORACLE = "oracle"  # evaluation only: accel - true_drift_mg, what perfect compensation would score
METHOD_ORDER = ("dlstm", "dlstm-ssa", "dlstm-issa", "pla", "poly3", "dlstm-temp", "persistence")
PAPER_METHODS = ("dlstm", "dlstm-ssa", "dlstm-issa", "pla")


@dataclass
class Comparison:
    """Fitted models, their scores, and how long each took to fit."""

    models: dict[str, Compensator]
    fit_seconds: dict[str, float]
    evaluation: Evaluation
    survival: dict[str, dict[str, InputSurvival]] = field(default_factory=dict)  # input rec -> method


def fit_all(
    train: Recording,
    settings: FusionSettings,
    *,
    methods: tuple[str, ...] = METHOD_ORDER,
    progress: bool = True,
    log: Callable[[str], None] = print,
) -> tuple[dict[str, Compensator], dict[str, float]]:
    """Fit every requested method on ``train`` (ground truth hidden)."""
    train = train.without_truth()
    models: dict[str, Compensator] = {}
    seconds: dict[str, float] = {}
    recursive = [m for m in ("dlstm", "dlstm-ssa", "dlstm-issa") if m in methods]
    if recursive:
        log(f"training the DLSTM population ({settings.population} x {settings.iterations} iterations)")
        start = time.perf_counter()
        probe = RecursiveDLSTM(settings=settings, progress=progress)
        x, y = probe.prepare(train)
        trained = train_stage(x, y, settings, progress=progress)
        shared = time.perf_counter() - start
        for method, cls in (
            ("dlstm", RecursiveDLSTM),
            ("dlstm-ssa", RecursiveDLSTMWithSSA),
            ("dlstm-issa", RecursiveDLSTMWithISSA),
        ):
            if method in recursive:
                log(f"fitting {method}")
                start = time.perf_counter()
                models[method] = cls(settings=settings, progress=progress).fit_from_population(train, trained)
                seconds[method] = shared + time.perf_counter() - start
    simple: dict[str, Callable[[], Compensator]] = {
        "pla": PiecewiseLinear,
        "poly3": CubicPolynomial,
        "dlstm-temp": lambda: TemperatureDLSTM(settings=settings, progress=progress),
        "persistence": Persistence,
    }
    for method, make in simple.items():
        if method in methods:
            log(f"fitting {method}")
            start = time.perf_counter()
            models[method] = make().fit(train)
            seconds[method] = time.perf_counter() - start
    return {m: models[m] for m in METHOD_ORDER if m in models}, seconds


def compare(
    train: Recording,
    valid: Recording,
    settings: FusionSettings,
    *,
    input_tests: tuple[Recording, ...] = (),
    smoothing_s: float = PAPER_RUN_SMOOTHING_S,
    methods: tuple[str, ...] = METHOD_ORDER,
    progress: bool = True,
    log: Callable[[str], None] = print,
) -> Comparison:
    models, seconds = fit_all(train, settings, methods=methods, progress=progress, log=log)
    blind = valid.without_truth()
    compensated = {name: model.compensate(blind) for name, model in models.items()}
    true_drift = valid.truth("drift_mg")
    if true_drift is not None:
        compensated[ORACLE] = valid.accel_mg - true_drift
    lo, hi = float(np.min(train.temp_c)), float(np.max(train.temp_c))
    outside = (valid.temp_c < lo) | (valid.temp_c > hi)
    evaluation = evaluate(
        valid,
        compensated,
        out_of_range={name: outside for name in models if name in ("pla", "poly3", "dlstm-temp")},
        smoothing_s=smoothing_s,
    )
    comparison = Comparison(models, seconds, evaluation)
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
