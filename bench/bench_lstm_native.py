"""Bench: the main job's DLSTM work with oneDNN's LSTM against the two LSTMs that could replace it.

``bench/bench_onednn_floor.py`` finds most of the main job's CPU time inside oneDNN's float32 LSTM
primitives (``torch.lstm`` on the packed groups). Two mathematically identical replacements exist
in this torch without new code: the same ``torch.lstm`` call with oneDNN switched off
(``torch.backends.mkldnn.enabled = False``: ATen's native LSTM, one gate matmul per time step)
and the reference backend ``backend="loop"`` (the whole population's gates as one ``torch.baddbmm``
per layer and time step, no packing). For each of the main job's four populations this runs a few
training iterations of all 10 networks (in the main job's packed groups, or all at once for
``loop``) and, for the shared population, a few fitness evaluations (a first iteration and a first
evaluation, which carry the set-up, not counted), in a fresh process per implementation; it
reports the CPU seconds of each (``time.process_time``), scaled to the main job's 500 iterations
and 2 x 201 evaluations, and whether the trained weights and the fitness values are the same bits
as oneDNN's (the condition for the printed tables to stay the same).

    python bench/bench_lstm_native.py out     # OUT of scripts/main_job.sh (train.npz, realistic-train.npz)
    python bench/bench_lstm_native.py out --iterations 1 --evaluations 1    # quicker
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from bench_onednn_floor import EVALUATIONS, ITERATIONS, POPULATIONS  # noqa: E402  (the same four)
from bench_population import cpu_model  # noqa: E402  (the machine named the same way in every bench)

from trainer import methods  # noqa: E402

IMPLEMENTATIONS = ("onednn", "native", "loop")
CHILD = """
import sys, time, torch
from trainer import methods as registry
from trainer.data.recording_io import read_recording
from trainer.dlstm.fusion import FusionSettings, as_batch, population_parts
from trainer.dlstm.network import LstmShape, PopulationDLSTM, forward_flat
from trainer.dlstm.train import per_individual_loss, train_population
from trainer.heap import keep_freed_memory
keep_freed_memory()
torch.set_num_threads(1)
recording, name, implementation, iterations, evaluations, result = sys.argv[1:]
iterations, evaluations = int(iterations), int(evaluations)
torch.backends.mkldnn.enabled = implementation != "native"
method = registry.REGISTRY[name]
x, y = method.cls(**method.options.compare_kwargs(FusionSettings(), False)).prepare(
    read_recording(recording).without_truth()
)
settings = FusionSettings()
xb, yb = as_batch(x, y)
backend = "loop" if implementation == "loop" else "packed"
initial = PopulationDLSTM(settings.population, xb.shape[-1], seed=settings.seed)
# the main job's packed groups, each trained alone; "loop" has no groups
parts = [range(settings.population)] if backend == "loop" else population_parts(settings)
train_s, individuals = 0.0, []
for part in parts:
    model = PopulationDLSTM.from_individuals([initial.individual(k) for k in part], backend=backend)
    stamps = []
    def stamp(_, __):
        stamps.append(time.process_time())
    train_population(model, xb, yb, lr=settings.lr, iterations=iterations + 1, seed=settings.seed,
                     progress=False, callback=stamp)
    train_s += stamps[-1] - stamps[0]  # the first iteration (set-up, first-call costs) not counted
    individuals += [model.individual(k) for k in range(len(part))]
trained = PopulationDLSTM.from_individuals(individuals).flatten()
theta, spec = initial.flatten(), LstmShape(xb.shape[-1])
with torch.no_grad():
    forward_flat(theta, xb, spec, backend=backend)  # warm-up, not counted
    start = time.process_time()
    for _ in range(evaluations):
        fitness = per_individual_loss(forward_flat(theta, xb, spec, backend=backend)[0], yb)
    evaluate_s = time.process_time() - start
torch.save({"theta": trained, "fitness": fitness, "train_s": train_s, "evaluate_s": evaluate_s}, result)
"""


def run_child(
    recording: Path, method: str, implementation: str, iterations: int, evaluations: int
) -> dict[str, Any]:
    """One implementation on one population in a fresh process; its saved result."""
    with tempfile.TemporaryDirectory() as tmp:
        result = Path(tmp) / "result.pt"
        env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
        argv = [str(recording), method, implementation, str(iterations), str(evaluations), str(result)]
        subprocess.run([sys.executable, "-c", CHILD, *argv], env=env, check=True)
        loaded: dict[str, Any] = torch.load(result, weights_only=False)
    return loaded


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="OUT of scripts/main_job.sh")
    parser.add_argument(
        "--iterations", type=int, default=2, help="training iterations timed (after one more)"
    )
    parser.add_argument(
        "--evaluations", type=int, default=2, help="fitness evaluations timed (after one more)"
    )
    args = parser.parse_args()
    if args.iterations < 1 or args.evaluations < 1:
        print("bench_lstm_native: --iterations and --evaluations must be >= 1", file=sys.stderr)
        return 2
    print(f"machine  : {platform.node()}, {cpu_model()}, os.cpu_count()={os.cpu_count()}")
    print(f"load     : {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    print(
        f"torch    : {torch.__version__}; {args.iterations} iterations, {args.evaluations} evaluations sampled"
    )
    totals = dict.fromkeys(IMPLEMENTATIONS, 0.0)
    for experiment, recording, method in POPULATIONS:
        results = {
            impl: run_child(args.out / recording, method, impl, args.iterations, args.evaluations)
            for impl in IMPLEMENTATIONS
        }
        reference = results["onednn"]
        for impl, r in results.items():
            train_s = r["train_s"] / args.iterations
            evaluate_s = r["evaluate_s"] / args.evaluations
            total_s = train_s * ITERATIONS + (evaluate_s * EVALUATIONS if method == methods.DLSTM else 0.0)
            totals[impl] += total_s
            weights_diff = float((r["theta"] - reference["theta"]).abs().max())
            fitness_differ = int((r["fitness"] != reference["fitness"]).sum())
            print(
                f"{experiment:<9} {method:<10} {impl:<6}: {train_s:6.2f} CPU-s per iteration of 10 networks, "
                f"{evaluate_s:5.2f} per evaluation -> {total_s:6.0f} CPU-s; weights max |diff| from oneDNN "
                f"{weights_diff:.2e}, fitness values differing {fitness_differ} of {r['fitness'].numel()}"
            )
    print("total    : " + ", ".join(f"{impl} {s:.0f} CPU-s" for impl, s in totals.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
