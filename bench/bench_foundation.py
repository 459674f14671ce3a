"""Benchmark of the foundation on the full paper recording (2 h at 200 Hz, 1.44 million rows).

Each stage runs in a fresh Python process so that its peak resident memory is its own (read with
``os.wait4``); the wall time is measured inside the process, around the work only (imports
excluded). Usage: ``python bench/bench_foundation.py [--workdir DIR]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

STAGES: dict[str, str] = {
    "simulate (paper-oven, 1.44 M samples)": """
        from trainer.physics.config import load_config
        from trainer.physics.simulate import simulate
        config = load_config(None)
        t0 = time.perf_counter(); rec = simulate(config, seed=1); elapsed = time.perf_counter() - t0
        from trainer.data.recording_io import write_recording
        write_recording(rec, WORK / "train.npz")
        extra = {"rows": len(rec)}
    """,
    "write CSV (1.44 M rows)": """
        from trainer.data.recording_io import read_recording, write_recording
        rec = read_recording(WORK / "train.npz")
        t0 = time.perf_counter(); write_recording(rec, WORK / "train.csv"); elapsed = time.perf_counter() - t0
        extra = {"columns": len(rec.columns), "MB": round((WORK / "train.csv").stat().st_size / 1e6, 1)}
    """,
    "load CSV (1.44 M rows)": """
        from trainer.data.recording_io import read_recording
        t0 = time.perf_counter(); rec = read_recording(WORK / "train.csv"); elapsed = time.perf_counter() - t0
        extra = {"rows": len(rec)}
    """,
    "load NPZ (1.44 M rows)": """
        from trainer.data.recording_io import read_recording
        t0 = time.perf_counter(); rec = read_recording(WORK / "train.npz"); elapsed = time.perf_counter() - t0
        extra = {"rows": len(rec)}
    """,
    "fit PLA (10 intervals)": """
        from trainer.data.recording_io import read_recording
        from trainer.fitting import fit_compensator
        from trainer.methods import MEMORYLESS, entries, name_of
        pla = [m.cls for m in entries() if m.family == MEMORYLESS][0]  # imports torch outside the timing
        rec = read_recording(WORK / "train.npz")
        t0 = time.perf_counter(); fit_compensator(name_of(pla), rec); elapsed = time.perf_counter() - t0
        extra = {}
    """,
    "fit cubic (PX4 recipe)": """
        from trainer.data.recording_io import read_recording
        from trainer.fitting import fit_compensator
        from trainer.methods import MEMORYLESS, entries, name_of
        cubic = [m.cls for m in entries() if m.family == MEMORYLESS][1]  # imports torch outside the timing
        rec = read_recording(WORK / "train.npz")
        t0 = time.perf_counter(); fit_compensator(name_of(cubic), rec); elapsed = time.perf_counter() - t0
        extra = {}
    """,
    "Allan deviation + N/B/K/R/Q": """
        from trainer.data.recording_io import read_recording
        from trainer.scoring.allan import allan_deviation, noise_coefficients
        rec = read_recording(WORK / "train.npz")
        t0 = time.perf_counter()
        curve = allan_deviation(rec.accel_mg, rec.sample_rate_hz)
        coeffs = noise_coefficients(curve)
        elapsed = time.perf_counter() - t0
        extra = {"taus": len(curve.taus_s), "B_mg": float(f"{coeffs.b_mg:.3g}")}
    """,
}

PRELUDE = """
import json, sys, time
from pathlib import Path
WORK = Path(sys.argv[1])
"""
EPILOGUE = """
print(json.dumps({"elapsed_s": elapsed, **extra}))
"""


def run_stage(code: str, workdir: Path) -> tuple[dict, float]:
    """Run one stage in a fresh interpreter; its JSON result and its peak RSS in MB."""
    script = PRELUDE + textwrap.dedent(code) + EPILOGUE
    proc = subprocess.Popen(
        [sys.executable, "-c", script, str(workdir)],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "TQDM_DISABLE": "1"},
    )
    assert proc.stdout is not None
    output = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"stage failed with exit code {proc.returncode}")
    return json.loads(output.strip().splitlines()[-1]), usage.ru_maxrss / 1024.0


def machine() -> str:
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.node()} | {cpu} | {os.cpu_count()} cores | Python {platform.python_version()}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--workdir", help="keep the generated recordings here (default: a temporary directory)"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(args.workdir or tmp)
        workdir.mkdir(parents=True, exist_ok=True)
        print(f"machine: {machine()}")
        print(f"{'stage':40s} {'wall (s)':>9s} {'peak RSS (MB)':>14s}  details")
        for name, code in STAGES.items():
            result, rss_mb = run_stage(code, workdir)
            elapsed = result.pop("elapsed_s")
            details = ", ".join(f"{k}={v}" for k, v in result.items())
            print(f"{name:40s} {elapsed:9.2f} {rss_mb:14.0f}  {details}", flush=True)


if __name__ == "__main__":
    main()
