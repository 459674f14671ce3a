"""One seeded draw (simulate the planned and the validation run, fit, score) and many of them.

A draw takes the target effects from their priors, simulates the training profile and the
independent validation profile with the same sensor (other noise), fits ``poly3`` and ``physics``
(automatic structure: the finder diagnoses the run, cross-validation completes it) on the training
run exactly as ``trainer compare`` does, and scores both on the validation run against the true
drift. The same draw index gives the same sensor on every profile (common random numbers).

On a further channel (a gyroscope axis: ``channel``) the targets replace that channel's effects
in the ``[channels.<name>]`` table, the accelerometer's physics stays as it is, and the draw fits and
scores the channel's one-channel view (its unit travels with it, as in ``trainer compare``).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np

from trainer import methods as registry
from trainer.data.recording import Recording
from trainer.fleet.cluster import TaskMap, task_map
from trainer.physics.catalogue import EFFECTS, excluded
from trainer.physics.config import ChannelConfig, PhysicsConfig, RecordingConfig
from trainer.physics.effects import EffectConfig
from trainer.plan.priors import Prior, draw_effects
from trainer.plan.programs import Program

CUBIC, PHYSICS = registry.CUBIC, registry.PHYSICS


@dataclass(frozen=True)
class DrawTask:
    base: PhysicsConfig  # the sensor without the targets (bias polynomial, temperature chain, noise)
    priors: tuple[Prior, ...]
    train: Program
    valid: Program
    seed: int
    index: int
    rate_hz: float
    channel: str | None = None  # a [channels.<name>] table of ``base`` to plan for (None: the accelerometer)


@dataclass(frozen=True)
class DrawResult:
    index: int
    truth: dict[str, dict[str, float]]
    fitted: dict[str, dict[str, float]]  # the physics compensator's effects (bias polynomial left out)
    error: dict[str, float]  # largest relative error of the checked parameters (inf: not found)
    drift_left: dict[str, float]  # method -> RMS against the true drift on the validation run (channel unit)

    @property
    def ratio(self) -> float:
        return self.drift_left[PHYSICS] / self.drift_left[CUBIC]


def sensor(
    base: PhysicsConfig,
    effects: Sequence[EffectConfig],
    program: Program,
    rate_hz: float,
    channel: str | None = None,
) -> PhysicsConfig:
    """``base`` on ``program`` with ``effects`` in place of the same identifiers (and of those they
    exclude): the accelerometer's, or with ``channel`` that channel's alone (the only channel kept)."""
    recording = RecordingConfig(rate_hz, base.recording.sensor)
    if channel is None:
        merged = merged_effects(base.effects, effects)
        return replace(base, recording=recording, protocol=program.protocol, effects=merged, channels=())
    own = next(c for c in base.channels if c.name == channel)
    table = ChannelConfig(channel, merged_effects(own.effects, effects), own.noise)
    return replace(base, recording=recording, protocol=program.protocol, channels=(table,))


def merged_effects(
    current: Sequence[EffectConfig], effects: Sequence[EffectConfig]
) -> tuple[EffectConfig, ...]:
    """``current`` with ``effects`` in place of the same identifiers and of those they exclude,
    in the catalogue's order."""
    names = {e.identifier for e in effects}
    kept = [e for e in current if not any(e.identifier == n or excluded(e.identifier, n) for n in names)]
    order = list(EFFECTS)
    return tuple(sorted((*kept, *effects), key=lambda e: order.index(e.identifier)))


def draw_seeds(seed: int, index: int) -> tuple[np.random.Generator, int, int]:
    """The priors' generator and the training and validation simulation seeds of draw ``index``."""
    sequence = np.random.SeedSequence([seed, index])
    priors_seq, train_seq, valid_seq = sequence.spawn(3)
    return (
        np.random.default_rng(priors_seq),
        int(train_seq.generate_state(1)[0]),
        int(valid_seq.generate_state(1)[0]),
    )


def _relative_error(prior: Prior, truth: EffectConfig, fitted: dict[str, dict[str, float]]) -> float:
    found = fitted.get(prior.identifier)
    if found is None:
        return math.inf
    return max(abs(found[name] - truth.params[name]) / abs(truth.params[name]) for name in prior.checked)


def run_draw(task: DrawTask) -> DrawResult:
    """Simulate, fit and score one draw (see the module docstring)."""
    from trainer.dlstm.fusion import FusionSettings
    from trainer.physics.simulate import simulate
    from trainer.scoring.compare import fit_all
    from trainer.scoring.evaluate import drift_score

    rng, train_seed, valid_seed = draw_seeds(task.seed, task.index)
    effects = draw_effects(task.priors, rng)
    train = _view(
        simulate(sensor(task.base, effects, task.train, task.rate_hz, task.channel), train_seed), task
    )
    valid = _view(
        simulate(sensor(task.base, effects, task.valid, task.rate_hz, task.channel), valid_seed), task
    )
    models, _ = fit_all(train, FusionSettings(), methods=(CUBIC, PHYSICS), progress=False, log=lambda _: None)
    blind = valid.without_truth()
    left = {}
    for name, model in models.items():
        t_ref = model.offset.t_ref_c if model.offset is not None and model.offset.relative else None
        score = drift_score(valid, model.compensate(blind), t_ref)
        assert score is not None, "a simulated recording carries its true drift"
        left[name] = score.residual_rms_mg
    fitted = {e.identifier: dict(e.params) for e in models[PHYSICS].effects}  # type: ignore[attr-defined]
    return DrawResult(
        task.index,
        {e.identifier: dict(e.params) for e in effects},
        fitted,
        {p.identifier: _relative_error(p, e, fitted) for p, e in zip(task.priors, effects, strict=True)},
        left,
    )


def _view(rec: Recording, task: DrawTask) -> Recording:
    """The planned channel's one-channel view (the recording itself for the accelerometer)."""
    from trainer.data.channels import channel_view, recording_channels

    return rec if task.channel is None else channel_view(rec, recording_channels(rec)[task.channel])


class Runner:
    """Maps draws in this process, on a process pool of Dask workers (LocalCluster) or an existing
    Dask cluster (:class:`trainer.fleet.cluster.TaskMap`), with a progress bar; results come back in
    task order."""

    def __init__(self, tasks: TaskMap, progress: bool = True) -> None:
        self.tasks = tasks
        self.progress = progress

    @property
    def width(self) -> int:
        """How many draws run at once."""
        return self.tasks.width

    def map(self, tasks: Sequence[DrawTask], desc: str) -> list[DrawResult]:
        from trainer.progress import progress_bar

        bar = progress_bar(progress=self.progress, total=len(tasks), desc=desc, unit="draw", leave=False)
        with bar:
            return self.tasks.map(run_draw, tasks, done=lambda _count, _task, _result: bar.update())


@contextmanager
def runner(workers: int, scheduler: str | None, progress: bool) -> Iterator[Runner]:
    """In this process for one worker, else on the project's Dask cluster (:mod:`trainer.fleet.cluster`)."""
    with task_map(workers, scheduler) as tasks:
        yield Runner(tasks, progress)
