"""``trainer compare --jobs N``: the comparison's fits side by side in N worker processes.

The results are those of fitting one method after another (``--jobs 1``; tested in
``tests/methods/test_side_by_side.py``): each task is one deterministic computation run with the caller's
torch thread count, and a DLSTM population trains in parts that are exact
(:func:`trainer.dlstm.fusion.population_parts`: its packed groups). The tasks:

- every part of each DLSTM population (the population the paper's three methods share, and
  ``dlstm-temp``'s own), the longest work, submitted first;
- every other method's fit (the recording goes to the worker);
- once a population is whole, the refinements of each method on it (best network, SSA, ISSA).

The workers ignore Ctrl-C, which the caller handles by terminating them (nothing partial is
written: the caller saves at the end).
"""

from __future__ import annotations

import multiprocessing
import queue
import signal
import sys
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any, Self

from trainer import methods as registry
from trainer.compensator import Compensator
from trainer.data.recording import Recording
from trainer.dlstm.compensators import StreamingDLSTM
from trainer.dlstm.fusion import (
    FusionResult,
    FusionSettings,
    Optimiser,
    TrainedPart,
    TrainedPopulation,
    join_parts,
    population_parts,
    refine_stage,
    train_part,
)

SHARED = "shared population"  # the key of the population the paper's methods share


def _worker_init(threads: int) -> None:
    import torch

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the caller handles Ctrl-C and terminates us
    torch.set_num_threads(threads)


def _timed(function: Callable[..., Any], *args: Any) -> tuple[Any, float]:
    start = time.perf_counter()
    return function(*args), time.perf_counter() - start


def _fit(model: Compensator, train: Recording) -> Compensator:
    return model.fit(train)


def _refine(
    trained: TrainedPopulation, x: Any, y: Any, settings: FusionSettings, optimiser: Optimiser
) -> FusionResult:
    return refine_stage(trained, x, y, settings, optimiser, progress=False)


class Workers:
    """A pool of worker processes; :meth:`next` returns results in the order they complete."""

    def __init__(self, jobs: int, threads: int) -> None:
        # Forked on Linux (as torch's DataLoader does): nothing to import again, and the workers are
        # this process's children, so their CPU time is counted in its own (bench/bench_pipeline.py).
        # Not after torch ran on more than one thread here: its OpenMP pool does not survive a fork, and
        # the workers hung at their first torch operation (trainer compare --jobs 2 --threads 2); they
        # start from a fresh server process then (their CPU time is not counted in this one's).
        import torch

        forkable = sys.platform == "linux" and torch.get_num_threads() == 1
        context = multiprocessing.get_context(
            "fork" if forkable else "forkserver" if sys.platform == "linux" else "spawn"
        )
        self._pool = context.Pool(jobs, initializer=_worker_init, initargs=(threads,))
        self._done: queue.Queue[tuple[Any, Any, BaseException | None]] = queue.Queue()
        self.pending = 0

    def submit(self, key: Any, function: Callable[..., Any], *args: Any) -> None:
        """Run ``function(*args)`` in a worker; :meth:`next` returns ``(key, (result, seconds))``."""
        self.pending += 1
        self._pool.apply_async(
            _timed,
            (function, *args),
            callback=lambda result: self._done.put((key, result, None)),
            error_callback=lambda error: self._done.put((key, None, error)),
        )

    def next(self) -> tuple[Any, tuple[Any, float]]:
        """The next finished task; its exception is raised here."""
        key, result, error = self._done.get()
        self.pending -= 1
        if error is not None:
            raise error
        return key, result

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        if kind is None:
            self._pool.close()
        else:  # an error or Ctrl-C: the other tasks' work is not wanted
            self._pool.terminate()
        self._pool.join()


def fit_side_by_side(
    train: Recording,
    chosen: list[registry.Method],
    build: Callable[[registry.Method], Compensator],
    settings: FusionSettings,
    *,
    jobs: int,
    threads: int,
    log: Callable[[str], None],
) -> tuple[dict[str, Compensator], dict[str, float]]:
    """Fit every method of ``chosen`` on ``train`` (ground truth already hidden) in ``jobs`` workers.

    Returns the fitted models (offset policy not applied) and, per method, the seconds its own
    tasks took in the workers (a shared population's training counts for each method using it).
    """
    models: dict[str, Compensator] = {}
    seconds: dict[str, float] = {}
    inputs: dict[str, tuple[Any, Any]] = {}  # population key -> standardised (x, y)
    on_population: dict[str, list[tuple[str, StreamingDLSTM]]] = {}  # population key -> its methods
    population_of: dict[str, str] = {}  # method -> population key
    waiting: dict[str, StreamingDLSTM] = {}
    others: list[tuple[str, Compensator]] = []
    for method in chosen:
        model = build(method)
        if isinstance(model, StreamingDLSTM):
            key = SHARED if method.shares_population else method.name
            x, y = model.prepare(train)
            inputs.setdefault(key, (x, y))
            on_population.setdefault(key, []).append((method.name, model))
            population_of[method.name] = key
            waiting[method.name] = model
        else:
            others.append((method.name, model))
    parts = population_parts(settings)
    trained_parts: dict[str, dict[int, TrainedPart]] = {key: {} for key in inputs}
    population_seconds = dict.fromkeys(inputs, 0.0)
    with Workers(jobs, threads) as workers:
        for key, (x, y) in inputs.items():
            log(
                f"training the {key} ({settings.population} x {settings.iterations} iterations) in {len(parts)} parts"
            )
            for index, part in enumerate(parts):
                workers.submit(("part", key, index), train_part, x, y, settings, part)
        for name, model in others:
            workers.submit(("fit", name, 0), _fit, model, train)
        while workers.pending:
            (kind, key, index), (result, took) = workers.next()
            if kind == "part":
                trained_parts[key][index] = result
                population_seconds[key] += took
                if len(trained_parts[key]) < len(parts):
                    continue
                trained = join_parts([trained_parts[key][i] for i in range(len(parts))])
                log(f"{key} trained ({population_seconds[key]:.1f} s in the workers)")
                x, y = inputs[key]
                for name, model in on_population[key]:
                    workers.submit(("refine", name, 0), _refine, trained, x, y, settings, model.optimiser)
            elif kind == "refine":
                models[key] = waiting.pop(key).adopt(result)
                seconds[key] = population_seconds[population_of[key]] + took
                log(f"{key} fitted")
            else:
                models[key] = result
                seconds[key] = took
                log(f"{key} fitted ({took:.1f} s)")
    return models, seconds
