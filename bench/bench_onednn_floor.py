"""Bench: the CPU seconds of the main job's DLSTM work spent inside oneDNN's LSTM primitives.

The trained weights (and so the printed tables) come from oneDNN's float32 LSTM (its ``ref``
training primitives and ``brgemm`` inference primitive, reached through ``torch.lstm``); another
implementation rounds differently, and the two that need no new code are far slower
(``bench/bench_lstm_native.py`` measures both). Their execution time is therefore a floor of the main job's
CPU time as long as the tables must stay the same. For each of the main job's four populations this
runs a few training iterations and fitness evaluations on the main job's own recordings with
``ONEDNN_VERBOSE=1``, sums the primitives' reported times and scales them to 500 iterations and to
the 2 x 201 evaluations of SSA and ISSA (on the shared population only).

    python bench/bench_onednn_floor.py out     # OUT of a finished scripts/main_job.sh
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from bench_population import cpu_model  # noqa: E402  (the machine named the same way in every bench)

from trainer import methods  # noqa: E402

ITERATIONS = 500  # FusionSettings' default
EVALUATIONS = 2 * 201  # SSA and ISSA: the initial population and 200 cycles each
SAMPLE_ITERATIONS = 4
POPULATIONS = (  # (experiment, training recording in OUT, method whose population it is)
    ("paper", "train.npz", methods.DLSTM),
    ("paper", "train.npz", methods.DLSTM_TEMP),
    ("realistic", "realistic-train.npz", methods.DLSTM),
    ("realistic", "realistic-train.npz", methods.DLSTM_TEMP),
)
CHILD = f"""
import sys, torch
from trainer import methods as registry
from trainer.data.recording_io import read_recording
from trainer.dlstm.fusion import FusionSettings, as_batch, train_part
from trainer.dlstm.network import LstmShape, PopulationDLSTM
from trainer.dlstm.train import population_loss
from trainer.heap import keep_freed_memory
keep_freed_memory()
torch.set_num_threads(1)
method = registry.REGISTRY[sys.argv[2]]
x, y = method.cls(**method.options.compare_kwargs(FusionSettings(), False)).prepare(
    read_recording(sys.argv[1]).without_truth()
)
print("PHASE train", flush=True)
train_part(x, y, FusionSettings(iterations={SAMPLE_ITERATIONS}), range(FusionSettings().population))
xb, yb = as_batch(x, y)
theta = PopulationDLSTM(FusionSettings().population, xb.shape[-1], seed=0).flatten()
print("PHASE evaluate", flush=True)
for _ in range({SAMPLE_ITERATIONS}):
    population_loss(theta, xb, yb, spec=LstmShape(xb.shape[-1]))
"""


def primitive_ms(text: str) -> tuple[float, float]:
    """(ms per training iteration, ms per fitness evaluation) of the LSTM primitives in a verbose log."""
    phase, train_ms, evaluate_ms = "", 0.0, 0.0
    for line in text.splitlines():
        if line.startswith("PHASE "):
            phase = line.split()[1]
        elif ",exec,cpu,rnn," in line:
            fields = line.split(",")
            kind, ms = fields[7], float(fields[-1])
            if phase == "train" and kind in ("forward_training", "backward"):
                train_ms += ms
            elif phase == "evaluate":
                evaluate_ms += ms
    return train_ms / SAMPLE_ITERATIONS, evaluate_ms / SAMPLE_ITERATIONS


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="OUT of a finished scripts/main_job.sh")
    args = parser.parse_args()
    print(f"machine  : {platform.node()}, {cpu_model()}, os.cpu_count()={os.cpu_count()}")
    print(f"load     : {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    env = {**os.environ, "ONEDNN_VERBOSE": "1", "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    total_s = 0.0
    for experiment, recording, method in POPULATIONS:
        done = subprocess.run(
            [sys.executable, "-c", CHILD, str(args.out / recording), method],
            env=env,
            capture_output=True,
            text=True,
            check=True,
        )
        train_ms, evaluate_ms = primitive_ms(done.stdout)
        train_s = train_ms * ITERATIONS / 1000
        evaluate_s = evaluate_ms * EVALUATIONS / 1000 if method == methods.DLSTM else 0.0
        total_s += train_s + evaluate_s
        print(
            f"{experiment:<9} {method:<10}: {train_ms:6.1f} ms per iteration of 10 networks -> "
            f"{train_s:6.1f} s; {evaluate_ms:5.1f} ms per fitness evaluation -> {evaluate_s:5.1f} s"
        )
    print(
        f"total    : {total_s:.0f} CPU-s in oneDNN's LSTM primitives; on 2 cores at least {total_s / 2:.0f} s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
