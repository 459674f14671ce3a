"""Frozen reference vectors: per method, a checked-in model file and the outputs the generated C
must give on a checked-in stream (``tests/data/ref/<method>.pt`` and ``.npz``).

The equivalence tests compare the C with the golden model; a change that moves both the same way
(a template and the golden model together) passes them. These files were produced once, by the
code that is itself tested against the float models (docs/codegen.md, "Error budget"), and are
only regenerated on purpose, when the arithmetic is meant to change:

    PYTHONPATH=. python -m tests.refvectors    # rewrites tests/data/ref/, then review the diff
    PYTHONPATH=. python -m tests.refvectors physics    # only one method's files (a new method)

Streams: 3,000 samples of a simulated oven run with a reset at sample 1,777, then bursts at the
input limits; streaming models step every 10 samples (front end of 50 ms windows), so 300 network
steps of a 2x10 network (or 2x4 for the temperature input, with a window longer than a period).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from tests import testmodels as tm
from trainer import methods as registry

REF_DIR = Path(__file__).resolve().parent / "data" / "ref"
SAMPLES = 3_000
RESET_AT = 1_777
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1


def methods() -> tuple[str, ...]:
    """One per distinct generated C (renderer and front-end kind)."""
    return tm.representatives()


def stream(seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A deterministic int32 stream (no simulator: the vectors must not move when it does)."""
    rng = np.random.default_rng(seed)
    t = np.arange(SAMPLES)
    temp = (25_000 + 40_000 * np.sin(t / 700.0) + rng.normal(0, 30, SAMPLES)).astype(np.int64)
    accel = (16_000_000 + 3.2 * (temp - 20_000) + rng.normal(0, 5_000, SAMPLES)).astype(np.int64)
    accel[2_500:2_550] = INT32_MAX
    accel[2_600:2_650] = INT32_MIN
    temp[2_700:2_760] = np.where(np.arange(60) % 2, INT32_MAX, INT32_MIN)
    return accel, temp


def _checkpoint(method: str) -> dict[str, object]:
    from trainer.cli import main as trainer_main
    from trainer.data.recording_io import read_recording

    work = REF_DIR / "_sim.npz"
    assert trainer_main(["simulate", "--seed", "2", "--duration", "300", "-o", str(work)]) == 0
    rec = read_recording(work)
    work.unlink()
    renderer = registry.get(method).renderer
    if renderer in ("pla", "cubic", "mean-stream", "physics"):
        return tm.checkpoint_for(method, rec)
    fe = tm.frontend_fields(200.0, run_s=0.05, temp_s=0.1, step_s=0.05)
    hidden = 4 if tm.frontend_kind(registry.REGISTRY[method]) == "temperature" else 10
    return tm.dlstm_checkpoint(method, rec, hidden=hidden, seed=5, frontend=fe)


def expected_outputs(model_path: Path) -> np.ndarray:
    """The golden model's outputs on :func:`stream` with a reset at RESET_AT."""
    from codegen.export import load_for_codegen
    from codegen.golden_select import golden_for

    golden = golden_for(load_for_codegen(model_path).quantised)
    accel, temp = load_stream() if (REF_DIR / "stream.npz").exists() else stream()
    first = golden.run(accel[:RESET_AT], temp[:RESET_AT])
    golden.reset()
    return np.concatenate((first, golden.run(accel[RESET_AT:], temp[RESET_AT:])))


def load_stream() -> tuple[np.ndarray, np.ndarray]:
    with np.load(REF_DIR / "stream.npz") as data:
        return data["accel"].astype(np.int64), data["temp"].astype(np.int64)


def load_outputs(method: str) -> np.ndarray:
    with np.load(REF_DIR / f"{method}.npz") as data:
        return data["out"].astype(np.int64)


def write_all(only: tuple[str, ...] = ()) -> None:
    """Every method's files (and the stream), or only those of the methods named (a new method)."""
    REF_DIR.mkdir(parents=True, exist_ok=True)
    if not only:
        accel, temp = stream()
        np.savez_compressed(REF_DIR / "stream.npz", accel=accel.astype(np.int32), temp=temp.astype(np.int32))
    for method in only or methods():
        path = REF_DIR / f"{method}.pt"
        tm.save_checkpoint(_checkpoint(method), path)
        out = expected_outputs(path).astype(np.int32)
        np.savez_compressed(REF_DIR / f"{method}.npz", out=out)
        print(f"{method}: {path.stat().st_size} B model, {out.size} outputs")


if __name__ == "__main__":
    write_all(tuple(sys.argv[1:]))  # python -m tests.refvectors [METHOD ...]
    sys.exit(0)
