"""Sparrow Search Algorithm (SSA) and the improved ISSA of Guo et al. (Sensors 2023, sect. 3.1.3).

The optimiser minimises a *batched* fitness: ``fitness(population)`` receives an array of
shape ``(pop, d)`` and returns ``(pop,)``.  Each iteration makes exactly ONE fitness call
on the whole new population, because the DLSTM fusion (sect. 3.1.4) evaluates its 10
networks as one batch.

Equations as implemented (rank ``i`` is 1-based in the population sorted best-first,
``n`` the population size, ``T`` = ``iterations``, ``t`` = 1, 2, ... the iteration):

* producers, ranks ``1..P`` (eq. (9); ISSA eq. (13)/(16))::

      R2 <  ST:  x_i <- x_i * exp(-i / (w * alpha_i * T))      w = 1 (SSA), w0 * c**t (ISSA)
      R2 >= ST:  x_i <- x_i + Q_i * ones(d)                   Q_i ~ N(0,1) (SSA), Lévy (ISSA)

* scroungers, ranks ``P+1..n`` (eq. (10); ISSA eq. (17))::

      i >  n/2:  x_i <- Q_i * exp((x_worst - x_i) / i**2)     Q_i ~ N(0,1) (SSA), Lévy (ISSA)
      i <= n/2:  x_i <- x_P + (|x_i - x_P| . A_i^+) * ones(d), A_i^+ = A_i^T (A_i A_i^T)^-1 = A_i^T / d

* scouters, a random subset of the whole population (eq. (11))::

      f_i >  f_b:  x_i <- x_b + beta_i * |x_i - x_b|                     beta_i ~ N(0, I_d)
      f_i == f_b:  x_i <- x_i + K_i * |x_i - x_worst| / ((f_i - f_w) + eps),  K_i ~ U[-1, 1]

* ISSA elitism: after evaluation, the previous generation's best replaces the current
  generation's worst.

Ambiguities of the paper, resolved after Xue & Shen's (2020) reference MATLAB code:

1. Ranks: the population is sorted by fitness each iteration; producers are the first
   ``round(producer_share * n)`` (>= 1); ``i`` in eq. (10) is the rank in the WHOLE
   population and ``n`` in ``i > n/2`` is the population size (``for i = pNum+1:pop;
   if i > pop/2``).
2. ``R2`` is drawn once per iteration for all producers; ``alpha`` once per producer in
   ``(0, 1]``; ``Q`` is one scalar per sparrow applied to every dimension (Xue's
   ``Q * L``, ``L = ones(1, d)``).  The Lévy step replaces ``Q`` one-for-one, so it is
   also one scalar per sparrow.
3. ``A^+ . L``: ``A`` is ``1 x d`` of +-1, so ``A A^T = d`` and ``A^+ = A^T / d``
   (``d x 1``).  ``|x_i - x_P|`` (``1 x d``) times ``A^+`` is the scalar
   ``sum_j A_j |x_ij - x_Pj| / d``, and times ``L`` (``1 x d``) it is broadcast to all
   dimensions -- the reference code's ``abs(pX - bestXX) * (A'*(A*A')^(-1)) * ones(1,dim)``.
   (Some re-implementations use the element-wise product ``|x_ij - x_Pj| A_j / d``; we do not.)
4. ``x_P`` in the ``i <= n/2`` branch is the NEW position of the best producer.  The
   reference code finds it by evaluating the producers first (a second fitness call per
   iteration); to keep one batched call we take the new position of the rank-1 producer.
5. ``x_worst``/``f_w`` are the worst of the current (pre-update) population; ``x_b``/``f_b``
   in eq. (11) are the best-so-far (global) position and fitness, so for minimisation
   ``f_i >= f_b`` always and the second branch is ``f_i == f_b``.  Scouters are
   ``round(scouter_share * n)`` sparrows drawn without replacement from the whole
   population (default share 0.2, the reference code's 20 of 100); their new position is
   computed from their pre-update position and fitness and overrides the producer or
   scrounger move (as in the reference code), which is what allows one evaluation per
   iteration.  ``eps = 1e-50`` as in the reference code.
6. ``ST = 0.8``; bounds (if given) are enforced by clipping after every move; the
   best-so-far solution is updated greedily.  Unlike the reference code there is no
   per-sparrow memory (``pX``/``pFit``): the population is replaced each generation, as
   Guo et al. describe -- with per-sparrow memory SSA would already be elitist and the
   ISSA elitism would change nothing.
7. ISSA's ``w = w0 * c**t`` uses ``t = 1`` in the first iteration.  Elitism only swaps
   when the elite is strictly better than the current worst (otherwise it would bring
   back a worse individual, against its stated purpose).

Known property: the producer rule ``x * exp(...)`` contracts toward the ORIGIN, and in
ISSA ``w`` becomes tiny after a few dozen iterations, so ``exp(-i / (w alpha T)) -> 0``
sends producers (and the scroungers following them) to the origin.  Problems whose
optimum is at the origin are therefore flattered.  ``producer_contraction="best"``
(an explicit, non-paper option) contracts the offset from the best-so-far position,
``x_b + (x_i - x_b) * exp(...)``; the default ``"origin"`` is the paper's rule.

Random draws per iteration, in order (for reproducibility): ``R2``; ``alpha`` (P);
producer jumps (P); scrounger signs ``A`` (S x d); scrounger jumps (S); scouter indices;
scouter ``beta`` (k x d); scouter ``K`` (k).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from trainer.dlstm.optim.levy import levy_step
from trainer.progress import progress_bar

__all__ = [
    "OptimizeResult",
    "SsaSettings",
    "apply_elitism",
    "minimize",
    "producer_update",
    "scouter_update",
    "scrounger_update",
]

Variant = Literal["ssa", "issa"]
Contraction = Literal["origin", "best"]
FitnessFn = Callable[[np.ndarray], ArrayLike]

SCOUTER_EPSILON = 1e-50  # eq. (11)'s epsilon, the reference code's value


@dataclass(frozen=True)
class SsaSettings:
    """The optimiser's parameters; the defaults are the paper's (and Xue & Shen's) values.

    ``iterations`` is also ``iter_max`` of the producer rule. ``population_size`` is used when
    :func:`minimize` draws the population (``None``: 30); with an initial population it must
    be ``None`` or agree with it. ``w0``, ``c`` and ``levy_beta`` are ISSA's only.
    ``producer_contraction="best"`` is the documented non-paper option (module docstring).
    Invalid values raise ``ValueError`` when the settings are made.
    """

    variant: Variant = "ssa"
    iterations: int = 200
    population_size: int | None = None
    producer_share: float = 0.2
    scouter_share: float = 0.2
    safety_threshold: float = 0.8
    w0: float = 1.0
    c: float = 0.9
    levy_beta: float = 1.5
    producer_contraction: Contraction = "origin"

    def __post_init__(self) -> None:
        if self.variant not in ("ssa", "issa"):
            raise ValueError(f"variant must be 'ssa' or 'issa', got {self.variant!r}")
        if self.producer_contraction not in ("origin", "best"):
            raise ValueError(
                f"producer_contraction must be 'origin' or 'best', got {self.producer_contraction!r}"
            )
        if not isinstance(self.iterations, int) or self.iterations < 0:
            raise ValueError(f"iterations must be a whole number >= 0, got {self.iterations!r}")
        if self.population_size is not None and (
            not isinstance(self.population_size, int) or self.population_size < 2
        ):
            raise ValueError(f"the population needs at least 2 sparrows, got {self.population_size!r}")
        unit_interval = (
            ("producer_share", self.producer_share),
            ("scouter_share", self.scouter_share),
            ("safety_threshold", self.safety_threshold),  # ST: an alarm value R2 is drawn in [0, 1]
        )
        for name, share in unit_interval:
            if not 0.0 <= share <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {share}")
        # ISSA's inertia w = w0 * c**t: positive and not growing (c > 1 would throw the producers out)
        if not 0.0 < self.w0 < math.inf:
            raise ValueError(f"w0 must be > 0 and finite, got {self.w0}")
        if not 0.0 < self.c <= 1.0:
            raise ValueError(f"c must lie in (0, 1], got {self.c}")
        if not 0.0 < self.levy_beta < 2.0:
            raise ValueError(f"levy_beta must lie in (0, 2), got {self.levy_beta}")


@dataclass(frozen=True)
class OptimizeResult:
    """Outcome of :func:`minimize` (also passed to the callback as a running snapshot).

    ``history[t]`` is the best-so-far fitness after iteration ``t`` (``history[0]`` is the
    initial population); ``population_best_history[t]`` is the best fitness *within* the
    population of generation ``t`` -- the quantity ISSA's elitism keeps from rising.
    """

    best_x: np.ndarray
    best_fitness: float
    history: np.ndarray
    population_best_history: np.ndarray
    n_evaluations: int
    n_iterations: int
    population: np.ndarray
    fitnesses: np.ndarray
    variant: str
    stopped_early: bool = False


def producer_update(
    positions: np.ndarray,
    ranks: np.ndarray,
    *,
    alarm: float,
    safety_threshold: float,
    alpha: np.ndarray,
    jumps: np.ndarray,
    iter_max: int,
    weight: float = 1.0,
    anchor: np.ndarray | None = None,
) -> np.ndarray:
    """Move producers by eq. (9) (SSA, ``weight=1``) or eq. (13)/(16) (ISSA).

    ``alarm`` is ``R2``; ``alpha`` (one per producer, in (0, 1]) and ``jumps`` (``Q`` or
    the Lévy step, one per producer) are the explicit random draws.  ``anchor=None`` is
    the paper's contraction toward the origin; an anchor vector contracts toward it.
    """
    positions = np.asarray(positions, dtype=float)
    ranks = np.asarray(ranks, dtype=float)
    if alarm >= safety_threshold:
        return positions + np.asarray(jumps, dtype=float)[:, None]
    scale = weight * np.asarray(alpha, dtype=float) * iter_max
    with np.errstate(divide="ignore", over="ignore", under="ignore"):
        # w -> 0 (ISSA, late iterations) gives -inf and a factor of exactly 0.
        factor = np.exp(-ranks / scale)[:, None]
    if anchor is None:
        return positions * factor
    anchor = np.asarray(anchor, dtype=float)
    return anchor + (positions - anchor) * factor


def scrounger_update(
    positions: np.ndarray,
    ranks: np.ndarray,
    *,
    population_size: int,
    leader: np.ndarray,
    worst: np.ndarray,
    signs: np.ndarray,
    jumps: np.ndarray,
) -> np.ndarray:
    """Move scroungers by eq. (10) (SSA) or eq. (17) (ISSA, Lévy ``jumps``).

    ``ranks`` are whole-population ranks; ``leader`` is ``x_P``; ``signs`` (``S x d`` of
    +-1) are the rows ``A_i``; ``jumps`` (one per scrounger) are ``Q`` or the Lévy step.
    """
    positions = np.asarray(positions, dtype=float)
    ranks = np.asarray(ranks, dtype=float)
    jumps = np.asarray(jumps, dtype=float)
    signs = np.asarray(signs, dtype=float)
    leader = np.asarray(leader, dtype=float)
    d = positions.shape[1]
    out = np.empty_like(positions)
    starving = ranks > population_size / 2
    with np.errstate(over="ignore", under="ignore"):
        out[starving] = jumps[starving, None] * np.exp(
            (np.asarray(worst, dtype=float) - positions[starving]) / ranks[starving, None] ** 2
        )
    follow = ~starving
    # |x_i - x_P| (1 x d) . A^+ (d x 1, = A^T / d) -> scalar, then . L broadcasts it.
    offset = np.sum(np.abs(positions[follow] - leader) * signs[follow], axis=1) / d
    out[follow] = leader + offset[:, None]
    return out


def scouter_update(
    positions: np.ndarray,
    fitnesses: np.ndarray,
    *,
    best_x: np.ndarray,
    best_fitness: float,
    worst_x: np.ndarray,
    worst_fitness: float,
    normal: np.ndarray,
    uniform: np.ndarray,
    epsilon: float = SCOUTER_EPSILON,
) -> np.ndarray:
    """Move scouters (sparrows aware of danger) by eq. (11).

    Sparrows worse than the best jump around the best (``normal`` is ``beta``, one
    N(0, 1) per element); the best sparrow itself moves relative to the worst
    (``uniform`` is ``K`` in [-1, 1], one per sparrow).
    """
    positions = np.asarray(positions, dtype=float)
    fitnesses = np.asarray(fitnesses, dtype=float)
    best_x = np.asarray(best_x, dtype=float)
    out = np.empty_like(positions)
    away = fitnesses > best_fitness
    out[away] = best_x + np.asarray(normal, dtype=float)[away] * np.abs(positions[away] - best_x)
    at_best = ~away
    denominator = (fitnesses[at_best] - worst_fitness) + epsilon
    step = np.abs(positions[at_best] - np.asarray(worst_x, dtype=float)) / denominator[:, None]
    out[at_best] = positions[at_best] + np.asarray(uniform, dtype=float)[at_best, None] * step
    return out


def apply_elitism(
    population: np.ndarray, fitnesses: np.ndarray, elite_x: np.ndarray, elite_fitness: float
) -> tuple[np.ndarray, np.ndarray]:
    """ISSA elitism: the previous generation's best replaces the current worst.

    The swap is skipped when the current worst is already at least as good as the elite.
    Returns new arrays; the inputs are not modified.
    """
    population = np.array(population, dtype=float)
    fitnesses = np.array(fitnesses, dtype=float)
    worst = int(np.argmax(fitnesses))
    if elite_fitness < fitnesses[worst]:
        population[worst] = elite_x
        fitnesses[worst] = elite_fitness
    return population, fitnesses


def _share_count(share: float, n: int, minimum: int) -> int:
    """``round(share * n)`` with halves rounded up (MATLAB ``round``), clamped to [minimum, n]."""
    return max(minimum, min(n, math.floor(share * n + 0.5)))


def _as_bound(value: ArrayLike | None, d: int, name: str) -> np.ndarray | None:
    if value is None:
        return None
    bound = np.broadcast_to(np.asarray(value, dtype=float), (d,)).copy()
    if np.isnan(bound).any():
        raise ValueError(f"{name} contains NaN")
    return bound


def _clip(x: np.ndarray, lower: np.ndarray | None, upper: np.ndarray | None) -> np.ndarray:
    if lower is not None:
        x = np.maximum(x, lower)
    if upper is not None:
        x = np.minimum(x, upper)
    return x


def _evaluate(fitness: FitnessFn, population: np.ndarray) -> np.ndarray:
    """One batched fitness call; NaN counts as +inf so it can never become the best."""
    values = np.asarray(fitness(population.copy()), dtype=float)
    if values.shape != (population.shape[0],):
        raise ValueError(
            f"fitness must return shape ({population.shape[0]},) for a population of shape "
            f"{population.shape}, got {values.shape}"
        )
    return np.where(np.isnan(values), np.inf, values)


def _draw_jumps(rng: np.random.Generator, size: int, variant: Variant, beta: float) -> np.ndarray:
    return levy_step(rng, size, beta) if variant == "issa" else rng.standard_normal(size)


def minimize(
    fitness: FitnessFn,
    initial_population: ArrayLike | None = None,
    *,
    seed: int | np.random.Generator,
    settings: SsaSettings = SsaSettings(),
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
    callback: Callable[[OptimizeResult], bool | None] | None = None,
    progress: bool = False,
) -> OptimizeResult:
    """Minimise a batched ``fitness`` with SSA or ISSA (see the module docstring).

    Either ``initial_population`` (shape ``(pop, d)``, e.g. trained networks) is given,
    or ``settings.population_size`` (default 30) sparrows are drawn uniformly in the finite
    box ``[lower, upper]`` (arrays of shape ``(d,)``; scalars broadcast when the other bound
    fixes ``d``).  ``lower``/``upper`` also clip every move.  ``callback`` receives a
    snapshot after each iteration and stops the run by returning ``True`` (the fusion's
    "accuracy meets the requirement" ending condition).  ``iter_max`` in the producer
    rule is ``settings.iterations`` even when a callback stops early.
    """
    variant, iterations, population_size = settings.variant, settings.iterations, settings.population_size
    rng = np.random.default_rng(seed)

    if initial_population is not None:
        population = np.array(initial_population, dtype=float)
        if population.ndim != 2:
            raise ValueError(f"initial_population must have shape (pop, d), got {population.shape}")
        if population_size is not None and population_size != population.shape[0]:
            raise ValueError("population_size disagrees with initial_population")
        n, d = population.shape
        lower_b, upper_b = _as_bound(lower, d, "lower"), _as_bound(upper, d, "upper")
        if not np.array_equal(_clip(population, lower_b, upper_b), population):
            raise ValueError("initial_population lies outside [lower, upper]")
    else:
        if lower is None or upper is None:
            raise ValueError("give initial_population, or both lower and upper to draw one")
        shape = np.broadcast(np.asarray(lower), np.asarray(upper)).shape
        if len(shape) != 1:
            raise ValueError("lower/upper must be arrays of shape (d,) to draw a population")
        n, d = population_size if population_size is not None else 30, shape[0]
        lower_b, upper_b = _as_bound(lower, d, "lower"), _as_bound(upper, d, "upper")
        assert lower_b is not None and upper_b is not None
        if not (np.isfinite(lower_b).all() and np.isfinite(upper_b).all() and (lower_b <= upper_b).all()):
            raise ValueError("lower/upper must be finite with lower <= upper to draw a population")
        population = lower_b + (upper_b - lower_b) * rng.random((n, d))
    if lower_b is not None and upper_b is not None and (lower_b > upper_b).any():
        raise ValueError("lower must not exceed upper")
    if n < 2:
        raise ValueError("the population needs at least 2 sparrows")

    n_producers = _share_count(settings.producer_share, n, minimum=1)
    n_scroungers = n - n_producers
    n_scouters = _share_count(settings.scouter_share, n, minimum=0)
    ranks = np.arange(1, n + 1, dtype=float)

    fitnesses = _evaluate(fitness, population)
    n_evaluations = n
    best_index = int(np.argmin(fitnesses))
    best_x, best_fitness = population[best_index].copy(), float(fitnesses[best_index])
    history = [best_fitness]
    population_best_history = [float(fitnesses.min())]

    def snapshot(n_iterations: int, stopped_early: bool = False) -> OptimizeResult:
        return OptimizeResult(
            best_x=best_x.copy(),
            best_fitness=best_fitness,
            history=np.array(history),
            population_best_history=np.array(population_best_history),
            n_evaluations=n_evaluations,
            n_iterations=n_iterations,
            population=population.copy(),
            fitnesses=fitnesses.copy(),
            variant=variant,
            stopped_early=stopped_early,
        )

    t = 0
    bar = progress_bar(range(1, iterations + 1), progress=progress, desc=variant.upper(), leave=False)
    for t in bar:
        order = np.argsort(fitnesses, kind="stable")
        population, fitnesses = population[order], fitnesses[order]
        worst_x, worst_fitness = population[-1], float(fitnesses[-1])
        weight = settings.w0 * settings.c**t if variant == "issa" else 1.0

        alarm = rng.random()
        alpha = 1.0 - rng.random(n_producers)  # (0, 1]
        producer_jumps = _draw_jumps(rng, n_producers, variant, settings.levy_beta)
        producers = producer_update(
            population[:n_producers],
            ranks[:n_producers],
            alarm=alarm,
            safety_threshold=settings.safety_threshold,
            alpha=alpha,
            jumps=producer_jumps,
            iter_max=iterations,
            weight=weight,
            anchor=best_x if settings.producer_contraction == "best" else None,
        )
        producers = _clip(producers, lower_b, upper_b)

        signs = rng.integers(0, 2, size=(n_scroungers, d)) * 2 - 1
        scrounger_jumps = _draw_jumps(rng, n_scroungers, variant, settings.levy_beta)
        scroungers = scrounger_update(
            population[n_producers:],
            ranks[n_producers:],
            population_size=n,
            leader=producers[0],
            worst=worst_x,
            signs=signs,
            jumps=scrounger_jumps,
        )
        new_population = np.concatenate([producers, _clip(scroungers, lower_b, upper_b)])

        scouts = rng.choice(n, size=n_scouters, replace=False)
        scouted = scouter_update(
            population[scouts],
            fitnesses[scouts],
            best_x=best_x,
            best_fitness=best_fitness,
            worst_x=worst_x,
            worst_fitness=worst_fitness,
            normal=rng.standard_normal((n_scouters, d)),
            uniform=rng.uniform(-1.0, 1.0, n_scouters),
        )
        new_population[scouts] = _clip(scouted, lower_b, upper_b)

        new_fitnesses = _evaluate(fitness, new_population)
        n_evaluations += n
        if variant == "issa":
            new_population, new_fitnesses = apply_elitism(
                new_population, new_fitnesses, population[0], float(fitnesses[0])
            )
        population, fitnesses = new_population, new_fitnesses

        generation_best = int(np.argmin(fitnesses))
        if fitnesses[generation_best] < best_fitness:
            best_x, best_fitness = population[generation_best].copy(), float(fitnesses[generation_best])
        history.append(best_fitness)
        population_best_history.append(float(fitnesses[generation_best]))
        if progress:
            bar.set_postfix(best=f"{best_fitness:.4g}")
        if callback is not None and callback(snapshot(t)):
            bar.close()
            return snapshot(t, stopped_early=True)
    bar.close()
    return snapshot(t)
