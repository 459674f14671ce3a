"""Gradient training of a :class:`~trainer.dlstm.network.PopulationDLSTM` (step 2 of the paper's fusion).

One iteration = one full-batch Adam step over the whole training sequence (the paper: learning
rate 0.02, 500 iterations; MATLAB's trainNetwork with 'adam', which is what such papers use).
Adam keeps its defaults (beta 0.9/0.999, eps 1e-8, as in MATLAB).

Independence: the objective is the *sum* of the per-individual losses, so individual p's
gradient is d loss_p / d theta_p only; Adam is element-wise and the optional clipping is per
individual. Training a population therefore equals training each individual alone.

Gradient clipping: off by default (MATLAB's GradientThreshold defaults to Inf). ``grad_clip=c``
rescales each individual's whole gradient to L2 norm <= c (MATLAB's 'global-l2norm', per network).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import torch
from torch import Tensor

from trainer.dlstm.network import LstmShape, PopulationDLSTM, forward_flat
from trainer.progress import progress_bar

LossKind = Literal["mse", "half_mse", "mae"]
# callback(iteration, per-individual losses (P,)) -> True to stop (the paper's "accuracy meets
# requirements" ending condition).
Callback = Callable[[int, Tensor], bool | None]


@dataclass
class TrainingHistory:
    """Per-individual losses of one training run."""

    losses: Tensor  # (iterations_done, P) float64: loss at each iteration, before its update
    final_loss: Tensor  # (P,) float64: loss after the last update
    iterations: int
    stopped_early: bool
    seconds: float

    def best(self) -> int:
        """Index of the individual with the lowest final loss (NaN counts as worst)."""
        return int(torch.nan_to_num(self.final_loss, nan=math.inf).argmin())


def one_step_ahead(series: Tensor) -> tuple[Tensor, Tensor]:
    """The real-time model's pairs (eq. (1)): inputs U(1..M-1), targets U(2..M).

    ``series`` (M,) or (B, M) -> inputs and targets, each (B, M-1, 1).
    """
    s = series.unsqueeze(0) if series.dim() == 1 else series
    if s.dim() != 2 or s.shape[1] < 2:
        raise ValueError(f"series must be (M,) or (B, M) with M >= 2, got {tuple(series.shape)}")
    return s[:, :-1].unsqueeze(-1), s[:, 1:].unsqueeze(-1)


def per_individual_loss(y: Tensor, targets: Tensor, loss: LossKind = "mse") -> Tensor:
    """(P,) loss of predictions y (P, B, T, out) against targets (B, T, out) or (P, B, T, out).

    A NaN target is no target: the network runs through that step (its state carries on) and the
    step is not scored, so a cross-validation fold's imputed rows are never learned."""
    missing = torch.isnan(targets)
    scored = None if not bool(missing.any()) else (~missing).expand_as(y)
    err = y - targets if scored is None else torch.where(scored, y - torch.nan_to_num(targets), 0.0)

    def mean(values: Tensor) -> Tensor:
        if scored is None:
            return values.flatten(1).mean(dim=1)
        return values.flatten(1).sum(dim=1) / scored.flatten(1).sum(dim=1).clamp(min=1).to(values.dtype)

    if loss == "mse":
        return mean(err.square())
    if loss == "half_mse":  # MATLAB regressionLayer
        return 0.5 * mean(err.square())
    if loss == "mae":
        return mean(err.abs())
    raise ValueError(f"loss must be 'mse', 'half_mse' or 'mae', got {loss!r}")


@torch.no_grad()
def population_loss(
    model_or_theta: PopulationDLSTM | Tensor,
    inputs: Tensor,
    targets: Tensor,
    *,
    spec: LstmShape | None = None,
    loss: LossKind = "mse",
) -> Tensor:
    """(P,) loss of every individual, no gradient: the sparrow search's fitness.

    Pass a module, or a (P', d) parameter matrix together with its ``spec``. Individuals with
    non-finite parameters get NaN without affecting the others.
    """
    if isinstance(model_or_theta, PopulationDLSTM):
        y, _ = model_or_theta(inputs)
    else:
        if spec is None:
            raise ValueError("population_loss needs spec= when given a parameter matrix")
        y, _ = forward_flat(model_or_theta, inputs, spec)
    return per_individual_loss(y, targets, loss)


def train_population(
    model: PopulationDLSTM,
    inputs: Tensor,
    targets: Tensor,
    *,
    lr: float = 0.02,
    iterations: int = 500,
    loss: LossKind = "mse",
    grad_clip: float | None = None,
    seed: int = 0,
    progress: bool = True,
    callback: Callback | None = None,
) -> TrainingHistory:
    """Train every individual of ``model`` in place with full-batch Adam.

    inputs (B, T, in) shared by all individuals or (P, B, T, in); targets (B, T, out) or
    (P, B, T, out), in the model's dtype; a NaN target is a step not scored (:func:`per_individual_loss`),
    an infinite one an error. Full-batch Adam has no random step; ``seed`` fixes
    torch's RNG inside the call (without disturbing the caller's) so the run stays reproducible
    if a stochastic option is ever added.
    """
    if iterations < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations}")
    if grad_clip is not None and not grad_clip > 0:
        raise ValueError(f"grad_clip must be > 0 or None, got {grad_clip}")
    if not bool(torch.isfinite(inputs).all()):
        raise ValueError("inputs contain NaN or inf")
    if bool(torch.isinf(targets).any()) or bool(torch.isnan(targets).all()):
        raise ValueError("targets contain inf, or NaN only (a NaN target is a step not scored)")
    params = model.param_list()
    P = model.population
    rows: list[Tensor] = []
    stopped = False
    start = time.perf_counter()
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        optimizer = torch.optim.Adam(params, lr=lr)
        bar = progress_bar(range(iterations), progress=progress, desc=f"DLSTM x{P}", unit="it", leave=False)
        for it in bar:
            optimizer.zero_grad(set_to_none=True)
            y, _ = model(inputs)
            losses = per_individual_loss(y, targets, loss)
            losses.sum().backward()
            if grad_clip is not None:
                clip_per_individual(params, grad_clip)
            optimizer.step()
            current = losses.detach().to(torch.float64)
            rows.append(current)
            if progress:
                bar.set_postfix(
                    best=f"{float(current.nan_to_num(math.inf).min()):.3g}",
                    median=f"{float(current.nanmedian()):.3g}",
                    refresh=False,
                )
            if callback is not None and callback(it, current.clone()):
                stopped = True
                break
        bar.close()
    final = population_loss(model, inputs, targets, loss=loss).to(torch.float64)
    losses_table = torch.stack(rows) if rows else torch.empty(0, P, dtype=torch.float64)
    return TrainingHistory(losses_table, final, len(rows), stopped, time.perf_counter() - start)


@torch.no_grad()
def clip_per_individual(params: list[torch.nn.Parameter], max_norm: float) -> None:
    """Scale each individual's gradient (all its tensors together) to L2 norm <= max_norm."""
    grads = [p.grad for p in params if p.grad is not None]
    if not grads:
        return
    P = grads[0].shape[0]
    norms = torch.stack([g.reshape(P, -1).square().sum(dim=1) for g in grads]).sum(dim=0).sqrt()
    scale = (max_norm / (norms + 1e-6)).clamp(max=1.0)
    for g in grads:
        g.mul_(scale.view(-1, *([1] * (g.dim() - 1))))
