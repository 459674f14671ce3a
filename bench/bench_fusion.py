"""Benchmark of the paper's full fusion configuration on a 2 h, 200 Hz training recording.

DLSTM + ISSA with 10 individuals x 500 gradient iterations and 200 ISSA cycles (section 4 of the
paper), on the built-in simulated paper experiment. Prints, in one run:

- wall time and peak resident memory of the whole fit (in a fresh process, read with os.wait4);
- the time of one training iteration and of one fitness evaluation of the population as one batch
  versus the same 10 networks one after another, on the same training sequence, and the
  resulting speed-up for the full configuration.

Usage: ``python bench/bench_fusion.py [--iterations 500] [--cycles 200] [--repeats 3]``
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_population import timed

FIT_SCRIPT = """
import json, sys, time, torch
torch.set_num_threads(1)
from trainer.physics.config import load_config
from trainer.physics.simulate import simulate
from trainer.dlstm.compensators import RecursiveDLSTMWithISSA
from trainer.dlstm.fusion import FusionSettings, refine_stage, train_stage
rec = simulate(load_config(None), seed=1).without_truth()
settings = FusionSettings(iterations=int(sys.argv[1]), cycles=int(sys.argv[2]))
model = RecursiveDLSTMWithISSA(settings=settings, progress=False)
start = time.perf_counter()
x, y = model.prepare(rec)
trained = train_stage(x, y, settings, progress=False)
middle = time.perf_counter()
model.adopt(refine_stage(trained, x, y, settings, "issa", progress=False))
elapsed = time.perf_counter() - start
t = model.training
print(json.dumps({"elapsed_s": elapsed, "steps": len(rec) // model.frontend.decimation,
                  "gradient_s": middle - start, "issa_s": elapsed - (middle - start),
                  "best_after_gradient": t["best_loss_after_gradient"], "best_after_issa": t["best_loss"]}))
"""


def run_fit(iterations: int, cycles: int) -> tuple[dict, float]:
    proc = subprocess.Popen(
        [sys.executable, "-c", FIT_SCRIPT, str(iterations), str(cycles)], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None
    output = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit("the fusion run failed")
    return json.loads(output.strip().splitlines()[-1]), usage.ru_maxrss / 1024.0


def batched_vs_sequential(repeats: int) -> dict[str, float]:
    """Per-iteration and per-fitness times, population as one batch vs one network at a time."""
    import numpy as np
    import torch

    from trainer.dlstm.network import PopulationDLSTM
    from trainer.dlstm.realtime import FrontEnd, smoothed_steps
    from trainer.dlstm.train import per_individual_loss, population_loss
    from trainer.physics.config import load_config
    from trainer.physics.simulate import simulate

    torch.set_num_threads(1)
    rec = simulate(load_config(None), seed=1)
    frontend = FrontEnd.from_seconds(rec.sample_rate_hz)
    u = smoothed_steps(rec.accel_mg, frontend.train_accel_window, frontend.decimation)
    u = (u - u.mean()) / u.std()
    x = torch.from_numpy(u[:-1].astype(np.float32)).reshape(1, -1, 1)
    y = torch.from_numpy(u[1:].astype(np.float32)).reshape(1, -1, 1)

    population = PopulationDLSTM(10, 1, seed=0)
    singles = [PopulationDLSTM.from_individuals([population.individual(k)]) for k in range(10)]
    batched_opt = torch.optim.Adam(population.parameters(), lr=0.02)
    single_opts = [torch.optim.Adam(m.parameters(), lr=0.02) for m in singles]

    def batched_iteration() -> None:
        batched_opt.zero_grad()
        out, _ = population(x)
        per_individual_loss(out, y).sum().backward()
        batched_opt.step()

    def sequential_iteration() -> None:
        for model, opt in zip(singles, single_opts, strict=True):
            opt.zero_grad()
            out, _ = model(x)
            per_individual_loss(out, y).sum().backward()
            opt.step()

    def batched_fitness() -> None:
        with torch.no_grad():
            population_loss(population, x, y)

    def sequential_fitness() -> None:
        with torch.no_grad():
            for model in singles:
                population_loss(model, x, y)

    return {
        "steps": x.shape[1],
        "iteration_batched_s": timed(batched_iteration, repeats),
        "iteration_sequential_s": timed(sequential_iteration, repeats),
        "fitness_batched_s": timed(batched_fitness, repeats),
        "fitness_sequential_s": timed(sequential_fitness, repeats),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=500)
    parser.add_argument("--cycles", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    import torch

    print(
        f"machine: {platform.node()} | {platform.machine()} | {os.cpu_count()} cores | "
        f"Python {platform.python_version()} | torch {torch.__version__} | 1 torch thread"
    )
    fit, rss_mb = run_fit(args.iterations, args.cycles)
    print(
        f"DLSTM+ISSA full fit: 10 individuals x {args.iterations} iterations + {args.cycles} ISSA cycles "
        f"on {fit['steps']} network steps (2 h at 200 Hz, 1 s steps)"
    )
    print(
        f"  wall time {fit['elapsed_s']:.1f} s (gradient {fit['gradient_s']:.1f} s, ISSA {fit['issa_s']:.1f} s)"
    )
    print(f"  peak RSS {rss_mb:.0f} MB")
    print(
        f"  training MSE (standardised): best after gradient {fit['best_after_gradient']:.3e}, "
        f"after ISSA {fit['best_after_issa']:.3e}"
    )
    timing = batched_vs_sequential(args.repeats)
    it_b, it_s = timing["iteration_batched_s"], timing["iteration_sequential_s"]
    fit_b, fit_s = timing["fitness_batched_s"], timing["fitness_sequential_s"]
    print(f"batched population vs one network at a time ({timing['steps']} steps, best of {args.repeats}):")
    print(f"  training iteration: {it_b * 1e3:.1f} ms vs {it_s * 1e3:.1f} ms -> speed-up {it_s / it_b:.2f}x")
    print(
        f"  fitness evaluation: {fit_b * 1e3:.1f} ms vs {fit_s * 1e3:.1f} ms -> speed-up {fit_s / fit_b:.2f}x"
    )
    full_b = args.iterations * it_b + args.cycles * fit_b
    full_s = args.iterations * it_s + args.cycles * fit_s
    print(
        f"  full configuration from these: {full_b:.0f} s vs {full_s:.0f} s -> speed-up {full_s / full_b:.2f}x"
    )


if __name__ == "__main__":
    main()
