"""Micro-benchmark: one population of P DLSTMs trained as a batch vs the same P networks one by one.

Measures, per sequence length and torch thread count, the time of one full-batch training
iteration (forward + backward + Adam step) and of one no-grad fitness evaluation, for

* batched:    one PopulationDLSTM holding all P individuals (one call),
* sequential: P single-individual PopulationDLSTM modules with the same weights, one after another,

for the fast ``packed`` backend and (for short sequences) the per-step ``loop`` reference.

    python bench/bench_population.py                      # P=10, T=1440 and 14400, threads 1 and 2
    python bench/bench_population.py --lengths 1440 --threads 2 --repeats 5
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Callable

import torch

from trainer.dlstm.network import DEFAULT_GROUP_SIZE, PopulationDLSTM
from trainer.dlstm.train import one_step_ahead, per_individual_loss, population_loss


def cpu_model() -> str:
    """The CPU's model name (Linux /proc/cpuinfo), else whatever platform knows."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def drift_sequence(length: int) -> tuple[torch.Tensor, torch.Tensor]:
    """One-step-ahead pairs of a smooth warm-up-like drift, ``length`` steps, float32."""
    t = torch.linspace(0.0, 1.0, length + 1, dtype=torch.float64)
    u = 1.0 - torch.exp(-t / 0.25) + 0.3 * t + 0.05 * torch.sin(40.0 * t)
    return one_step_ahead(((u - u.mean()) / u.std()).float())


def timed(fn: Callable[[], object], repeats: int) -> float:
    """Best of ``repeats`` calls after one warm-up call (oneDNN builds its kernels then).

    The minimum, as timeit recommends: on a shared machine the others only add noise.
    """
    fn()
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - start)
    return min(samples)


def training_iteration(
    models: list[PopulationDLSTM], inputs: torch.Tensor, targets: torch.Tensor
) -> Callable[[], None]:
    optimizers = [torch.optim.Adam(m.parameters(), lr=0.02) for m in models]

    def run() -> None:
        for model, optimizer in zip(models, optimizers, strict=True):
            optimizer.zero_grad(set_to_none=True)
            y, _ = model(inputs)
            per_individual_loss(y, targets).sum().backward()
            optimizer.step()

    return run


def fitness(models: list[PopulationDLSTM], inputs: torch.Tensor, targets: torch.Tensor) -> Callable[[], None]:
    def run() -> None:
        for model in models:
            population_loss(model, inputs, targets)

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--population", type=int, default=10)
    parser.add_argument("--lengths", type=int, nargs="+", default=[1440, 14400])
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--loop-max-length",
        type=int,
        default=1440,
        help="run the per-step reference backend only up to this length (it is slow)",
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    P = args.population
    print(f"platform : {platform.platform()} ({platform.machine()}), python {platform.python_version()}")
    print(
        f"cpu      : {cpu_model()}, os.cpu_count()={os.cpu_count()}, "
        f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}"
    )
    print(f"torch    : {torch.__version__}, mkldnn available={torch.backends.mkldnn.is_available()}")
    print(
        f"model    : P={P}, 2 layers x 10 units, input 1, output 1, float32, packed group size "
        f"{DEFAULT_GROUP_SIZE}; best of {args.repeats} (loop backend: best of 2)"
    )
    print()
    columns = ("threads", 7), ("T", 6), ("backend", 7), ("what", 9), ("batched", 10), ("sequential", 11)
    header = " ".join(f"{name:>{width}}" for name, width in columns) + f" {'speed-up':>8}"
    print(header)
    print("-" * len(header))
    for threads in args.threads:
        torch.set_num_threads(threads)
        for length in args.lengths:
            inputs, targets = drift_sequence(length)
            for backend in ("packed", "loop"):
                if backend == "loop" and length > args.loop_max_length:
                    continue
                batched = PopulationDLSTM(P, 1, seed=args.seed, backend=backend)
                singles = [
                    PopulationDLSTM.from_individuals([batched.individual(k)], backend=backend)
                    for k in range(P)
                ]
                repeats = args.repeats if backend == "packed" else min(args.repeats, 2)
                for what, make in (("train it", training_iteration), ("fitness", fitness)):
                    t_batched = timed(make([batched], inputs, targets), repeats)
                    t_sequential = timed(make(singles, inputs, targets), repeats)
                    print(
                        f"{threads:>7} {length:>6} {backend:>7} {what:>9} {t_batched * 1e3:>8.1f}ms "
                        f"{t_sequential * 1e3:>9.1f}ms {t_sequential / t_batched:>7.2f}x"
                    )
                    if what == "train it" and backend == "packed":
                        print(
                            f"{'':>32}-> 500 iterations ~ {500 * t_batched:.0f} s batched, "
                            f"{500 * t_sequential:.0f} s sequential"
                        )


if __name__ == "__main__":
    main()
