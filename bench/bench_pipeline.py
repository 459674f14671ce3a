"""Bench: the main job one step after another (JOBS=1) against side by side (JOBS=N), in one run.

Runs ``scripts/main_job.sh`` (the main job without set-up) twice, into OUT/before (``JOBS=1``:
every simulation, comparison and fit one after another, as the main job ran before) and
OUT/after (``JOBS=N``: simulations, the three comparisons and each comparison's fits side by side).
Reports each run's wall time and CPU seconds (user + system of every process it started), the
ratios, the machine and its load, and checks that the printed tables are the same to the digit
(the fit-time column, a wall-clock measurement, apart). On a shared machine the wall times are
noisy; the CPU seconds and the ratio of one run are what to compare.

    python bench/bench_pipeline.py                    # the full main job twice (about 13 min quiet, 2 cores)
    python bench/bench_pipeline.py --out /tmp/bench -- --iterations 50 --cycles 20   # shorter
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from bench_population import cpu_model  # noqa: E402  (the machine named the same way in every bench)

TABLES = ("comparison", "realistic", "realistic-gyro")  # scripts/main_job.sh's $OUT/NAME.txt
TIME_COLUMN = "fit time (s)"


def children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run(out: Path, jobs: int, extra: list[str]) -> tuple[float, float]:
    """(wall s, CPU s) of one main job into ``out`` with ``JOBS=jobs``."""
    env = {**os.environ, "OUT": str(out), "JOBS": str(jobs), "PYTHONPATH": str(ROOT)}
    cpu, start = children_cpu_s(), time.perf_counter()
    with open(out.with_suffix(".log"), "w", encoding="utf-8") as log:
        subprocess.run(
            ["bash", str(ROOT / "scripts" / "main_job.sh"), *extra],
            env=env,
            stdout=log,
            stderr=log,
            check=True,
        )
    return time.perf_counter() - start, children_cpu_s() - cpu


def without_time_column(text: str, out: Path) -> list[str]:
    """The printed lines with the fit-time cell of every table that has one removed and the
    output folder ``out`` named OUT."""
    lines, drop = [], None
    text = text.replace(str(out), "OUT")
    for line in text.splitlines():
        cells = line.split("|")
        if line.startswith("|") and TIME_COLUMN in cells[-2]:
            drop = len(cells) - 2
        elif not line.startswith("|"):
            drop = None
        if drop is not None and len(cells) > drop:
            cells = cells[:drop] + cells[drop + 1 :]
        lines.append("|".join(cells))
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "bench-pipeline")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="JOBS of the 'after' run")
    parser.add_argument("extra", nargs="*", help="arguments for trainer compare (after --)")
    args = parser.parse_args()
    print(f"machine  : {platform.node()}, {cpu_model()}, os.cpu_count()={os.cpu_count()}")
    print(f"platform : {platform.platform()}, python {platform.python_version()}")
    results = {}
    for label, jobs in (("before", 1), ("after", args.jobs)):
        out = args.out / label
        out.mkdir(parents=True, exist_ok=True)
        load = " ".join(f"{v:.2f}" for v in os.getloadavg())
        wall, cpu = run(out, jobs, args.extra)
        results[label] = (wall, cpu)
        print(f"{label:<7}: JOBS={jobs}: wall {wall:7.1f} s, CPU {cpu:7.1f} s (load average at start {load})")
    (wall_b, cpu_b), (wall_a, cpu_a) = results["before"], results["after"]
    print(f"ratio  : wall before/after {wall_b / wall_a:.2f}x, CPU after/before {cpu_a / cpu_b:.2f}")
    same = True
    for name in TABLES:
        before, after = (
            without_time_column(
                (args.out / label / f"{name}.txt").read_text(encoding="utf-8"), args.out / label
            )
            for label in ("before", "after")
        )
        if before != after:
            same = False
            print(
                f"tables : {name}: DIFFERENT (diff {args.out}/before/{name}.txt {args.out}/after/{name}.txt)"
            )
    if same:
        print(f"tables : the same to the printed digit ({', '.join(TABLES)}; fit times apart)")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
