"""trainer/heap.py: keeping freed memory changes no bit of the training.

Each case trains the same small DLSTM population in a fresh process (the allocator's settings are
per process), once with glibc's defaults and once after :func:`trainer.heap.keep_freed_memory`.
What the setting buys (page faults, time) depends on the machine and its load, so it is measured
in ``bench/bench_pipeline.py`` (its page-fault column), not asserted here: on one machine the
defaults' 8 iterations took 2,477 to 20,546 faults against 66 to 1,735 kept, on another, loaded,
1,513 against 1,739.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
STEPS = 6000  # long enough that every workspace is served by mmap under glibc's defaults

CHILD = f"""
import hashlib, json, sys
import numpy as np, torch
from trainer.heap import keep_freed_memory
from trainer.dlstm.fusion import FusionSettings, train_stage
kept = keep_freed_memory() if sys.argv[1] == "keep" else None
torch.set_num_threads(1)
t = np.linspace(0.0, 1.0, {STEPS} + 1)
series = np.sin(6.0 * t) + 0.5 * t
x, y = series[:-1].reshape(-1, 1), series[1:]
train_stage(x, y, FusionSettings(population=3, iterations=2), progress=False)  # warm-up
trained = train_stage(x, y, FusionSettings(population=3, iterations=8), progress=False)
digest = hashlib.sha256(trained.model.flatten().numpy().tobytes()).hexdigest()
print(json.dumps({{"kept": kept, "weights": digest}}))
"""


def _train(mode: str) -> dict[str, object]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    for name in ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_"):
        env.pop(name, None)  # glibc's own defaults for the reference run
    done = subprocess.run(
        [sys.executable, "-c", CHILD, mode], env=env, capture_output=True, text=True, check=True
    )
    result: dict[str, object] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_kept_memory_trains_the_same_bits() -> None:
    default, kept = _train("default"), _train("keep")
    assert default["kept"] is None and kept["kept"] is True  # the setting took effect in one only
    assert kept["weights"] == default["weights"]
