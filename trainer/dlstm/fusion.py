"""The paper's fusion algorithm (section 3.1.4, Figure 8): DLSTM population + SSA/ISSA.

1. ``population`` DLSTMs with random initial weights (seeded per individual).
2. Gradient training (Adam, ``lr``) of the whole population as one batch until ending condition
   one: ``iterations`` reached, or every individual's loss at or below ``target_loss``.
3. The trained parameter vectors are the initial sparrows; SSA or ISSA runs ``cycles`` iterations
   with the batched training loss as fitness (ending condition two: ``cycles`` or
   ``target_loss``).
4. The best vector found is exported.

Stage 2 and stage 3 are separate functions so that ``trainer compare`` trains one population
and refines it with SSA and with ISSA, exactly as the paper compares them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import torch

from trainer.dlstm.network import PopulationDLSTM, packed_groups
from trainer.dlstm.optim import SsaSettings, minimize
from trainer.dlstm.train import TrainingHistory, population_loss, train_population
from trainer.errors import UserError

Optimiser = Literal["none", "ssa", "issa"]


@dataclass(frozen=True)
class FusionSettings:
    """The paper's section 4 settings, all configurable."""

    population: int = 10
    hidden_size: int = 10
    num_layers: int = 2
    lr: float = 0.02
    iterations: int = 500
    cycles: int = 200
    target_loss: float | None = None
    seed: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items()}


@dataclass
class TrainedPopulation:
    """Stage 2's result: the trained population and its per-iteration losses."""

    model: PopulationDLSTM
    history: TrainingHistory
    seconds: float


@dataclass
class FusionResult:
    """What the exported model records about its training."""

    weights: dict[str, torch.Tensor]
    optimiser: Optimiser
    train_loss_per_iteration: list[float]  # best individual's loss after each gradient step
    population_loss_before: list[float]  # (P,) after gradient training
    best_loss: float
    optimiser_history: list[float] = field(default_factory=list)  # best fitness per cycle
    seconds_gradient: float = 0.0
    seconds_optimiser: float = 0.0

    def summary(self) -> dict[str, Any]:
        """What the checkpoint records. No wall-clock times: the same inputs must give a
        byte-identical model.pt (and so the same model id in the generated C)."""
        return {
            "optimiser": self.optimiser,
            "best_loss": self.best_loss,
            "population_loss_after_gradient": self.population_loss_before,
            "best_loss_after_gradient": float(np.nanmin(self.population_loss_before)),
            "train_loss_per_iteration": self.train_loss_per_iteration,
            "optimiser_best_per_cycle": self.optimiser_history,
        }


def as_batch(inputs: np.ndarray, targets: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """(T, in), (T,) numpy -> (1, T, in), (1, T, 1) float32 tensors."""
    x = torch.from_numpy(np.ascontiguousarray(inputs, dtype=np.float32)).reshape(1, len(inputs), -1)
    y = torch.from_numpy(np.ascontiguousarray(targets, dtype=np.float32)).reshape(1, len(targets), 1)
    return x, y


def _initial_population(input_size: int, settings: FusionSettings) -> PopulationDLSTM:
    """Stage 1: the seeded random population (individual k depends on (seed, k) only)."""
    torch.manual_seed(settings.seed)
    return PopulationDLSTM(
        settings.population,
        input_size,
        settings.hidden_size,
        settings.num_layers,
        1,
        seed=settings.seed,
    )


def _train(
    model: PopulationDLSTM, x: torch.Tensor, y: torch.Tensor, settings: FusionSettings, progress: bool
) -> TrainingHistory:
    """Stage 2 on ``model`` in place: Adam until ending condition one."""

    def reached_target(_: int, losses: torch.Tensor) -> bool:
        return settings.target_loss is not None and bool(torch.all(losses <= settings.target_loss))

    return train_population(
        model,
        x,
        y,
        lr=settings.lr,
        iterations=settings.iterations,
        seed=settings.seed,
        progress=progress,
        callback=reached_target,
    )


def train_stage(
    inputs: np.ndarray, targets: np.ndarray, settings: FusionSettings, *, progress: bool = True
) -> TrainedPopulation:
    """Stage 1-2: initialise and gradient-train the population (ending condition one)."""
    x, y = as_batch(inputs, targets)
    model = _initial_population(x.shape[-1], settings)
    start = time.perf_counter()
    history = _train(model, x, y, settings, progress)
    return TrainedPopulation(model, history, time.perf_counter() - start)


# -- stage 2 in parts, side by side (trainer compare --jobs) ------------------------------------


@dataclass
class TrainedPart:
    """Some individuals of the population, gradient-trained alone (:func:`train_part`)."""

    individuals: list[dict[str, torch.Tensor]]
    history: TrainingHistory


def population_parts(settings: FusionSettings) -> list[range]:
    """Parts of the population that train alone exactly as inside the whole: its packed groups.

    The loss is a sum over individuals, Adam is element-wise and a group's arithmetic depends on
    that group only (:func:`~trainer.dlstm.network.packed_groups`). One part when ``target_loss``
    is set: that ending condition looks at every individual at once.
    """
    if settings.target_loss is not None:
        return [range(settings.population)]
    return packed_groups(settings.population)


def train_part(inputs: np.ndarray, targets: np.ndarray, settings: FusionSettings, part: range) -> TrainedPart:
    """Stage 1-2 for the individuals ``part`` of the population only (no progress bar)."""
    x, y = as_batch(inputs, targets)
    whole = _initial_population(x.shape[-1], settings)
    model = PopulationDLSTM.from_individuals([whole.individual(k) for k in part])
    history = _train(model, x, y, settings, progress=False)
    return TrainedPart([model.individual(k) for k in range(len(part))], history)


def join_parts(parts: list[TrainedPart]) -> TrainedPopulation:
    """The whole trained population from its parts (in population order), as :func:`train_stage`
    would have returned it; ``seconds`` is the parts' training time summed."""
    model = PopulationDLSTM.from_individuals([ind for part in parts for ind in part.individuals])
    histories = [part.history for part in parts]
    history = TrainingHistory(
        losses=torch.cat([h.losses for h in histories], dim=1),
        final_loss=torch.cat([h.final_loss for h in histories]),
        iterations=histories[0].iterations,
        stopped_early=histories[0].stopped_early,
        seconds=sum(h.seconds for h in histories),
    )
    return TrainedPopulation(model, history, history.seconds)


def refine_stage(
    trained: TrainedPopulation,
    inputs: np.ndarray,
    targets: np.ndarray,
    settings: FusionSettings,
    optimiser: Optimiser,
    *,
    progress: bool = True,
) -> FusionResult:
    """Stage 3-4: SSA/ISSA over the trained population (or none), export the best vector."""
    x, y = as_batch(inputs, targets)
    model = trained.model
    with torch.no_grad():
        losses = population_loss(model, x, y).double().numpy()
    per_iteration = [float(np.nanmin(row)) for row in trained.history.losses.double().numpy()]
    result = FusionResult(
        weights={},
        optimiser=optimiser,
        train_loss_per_iteration=per_iteration,
        population_loss_before=[float(v) for v in losses],
        best_loss=float(np.nanmin(losses)),
        seconds_gradient=trained.seconds,
    )
    if np.all(np.isnan(losses)):  # nothing to choose from: said in one line, not an All-NaN traceback
        raise UserError(
            f"every one of the {len(losses)} DLSTMs diverged in training (loss NaN): try a smaller --lr "
            f"(given {settings.lr:g})"
        )
    if optimiser == "none" or (settings.target_loss is not None and result.best_loss <= settings.target_loss):
        best = int(np.nanargmin(losses))
        result.weights = model.individual(best)
        return result

    spec = model.spec

    def fitness(population: np.ndarray) -> np.ndarray:
        theta = torch.from_numpy(population.astype(np.float32))
        with torch.no_grad():
            return population_loss(theta, x, y, spec=spec).double().numpy()

    def reached_target(snapshot: Any) -> bool:
        return settings.target_loss is not None and snapshot.best_fitness <= settings.target_loss

    start = time.perf_counter()
    outcome = minimize(
        fitness,
        model.flatten().detach().double().numpy(),
        seed=settings.seed,
        settings=SsaSettings(variant=optimiser, iterations=settings.cycles),
        callback=reached_target,
        progress=progress,
    )
    result.seconds_optimiser = time.perf_counter() - start
    result.optimiser_history = [float(v) for v in outcome.history]
    best_theta = torch.from_numpy(np.asarray(outcome.best_x, dtype=np.float32)).reshape(1, -1)
    single = PopulationDLSTM(1, spec.input_size, spec.hidden_size, spec.num_layers, spec.output_size, seed=0)
    single.load_flat(best_theta)
    result.weights = single.individual(0)
    with torch.no_grad():
        result.best_loss = float(population_loss(single, x, y)[0])
    return result


def fuse(
    inputs: np.ndarray,
    targets: np.ndarray,
    settings: FusionSettings,
    optimiser: Optimiser,
    *,
    progress: bool = True,
) -> FusionResult:
    """The whole fusion algorithm for one optimiser."""
    trained = train_stage(inputs, targets, settings, progress=progress)
    return refine_stage(trained, inputs, targets, settings, optimiser, progress=progress)
