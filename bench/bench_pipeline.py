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

``--before-rev REV`` compares code instead of JOBS: "before" is the main job of git revision REV
(checked out into a temporary worktree, removed afterwards), "after" this checkout's, both with
``JOBS=--jobs``; e.g. ``--before-rev HEAD~3`` for the effect of the last three commits.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from bench_population import cpu_model  # noqa: E402  (the machine named the same way in every bench)

TABLES = ("comparison", "realistic", "realistic-gyro")  # scripts/main_job.sh's $OUT/NAME.txt
TIME_COLUMN = "fit time (s)"


@dataclass(frozen=True)
class Usage:
    """What one main job took: wall time, user and system CPU of every process it started, and
    their minor page faults (each a 4 KiB page the kernel mapped and zeroed)."""

    wall_s: float
    user_s: float
    system_s: float
    page_faults: int

    @property
    def cpu_s(self) -> float:
        return self.user_s + self.system_s


def children_usage() -> tuple[float, float, int]:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime, usage.ru_stime, usage.ru_minflt


def run(out: Path, jobs: int, extra: list[str], root: Path = ROOT) -> Usage:
    """One main job of the checkout ``root`` into ``out`` with ``JOBS=jobs``."""
    env = {**os.environ, "OUT": str(out), "JOBS": str(jobs), "PYTHONPATH": str(root)}
    (user, system, faults), start = children_usage(), time.perf_counter()
    with open(out.with_suffix(".log"), "w", encoding="utf-8") as log:
        subprocess.run(
            ["bash", str(root / "scripts" / "main_job.sh"), *extra],
            env=env,
            stdout=log,
            stderr=log,
            check=True,
        )
    wall = time.perf_counter() - start
    user_after, system_after, faults_after = children_usage()
    return Usage(wall, user_after - user, system_after - system, faults_after - faults)


@contextmanager
def checkout(rev: str | None, where: Path) -> Iterator[Path]:
    """This checkout (``rev`` None), or revision ``rev`` in a temporary git worktree at ``where``."""
    if rev is None:
        yield ROOT
        return
    git = ["git", "-C", str(ROOT)]
    subprocess.run([*git, "worktree", "add", "--detach", str(where), rev], check=True, capture_output=True)
    try:
        yield where
    finally:
        subprocess.run([*git, "worktree", "remove", "--force", str(where)], check=True, capture_output=True)


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
    parser.add_argument(
        "--before-rev", help="'before' is this git revision's main job (JOBS=--jobs), not JOBS=1"
    )
    parser.add_argument("extra", nargs="*", help="arguments for trainer compare (after --)")
    args = parser.parse_args()
    print(f"machine  : {platform.node()}, {cpu_model()}, os.cpu_count()={os.cpu_count()}")
    print(f"platform : {platform.platform()}, python {platform.python_version()}")
    results = {}
    runs = (
        (("before", 1, None), ("after", args.jobs, None))
        if args.before_rev is None
        else (("before", args.jobs, args.before_rev), ("after", args.jobs, None))
    )
    for label, jobs, rev in runs:
        out = args.out / label
        out.mkdir(parents=True, exist_ok=True)
        load = " ".join(f"{v:.2f}" for v in os.getloadavg())
        with checkout(rev, args.out / "before-checkout") as root:
            used = run(out, jobs, args.extra, root)
        results[label] = used
        code = f"revision {rev}" if rev else "this checkout"
        print(
            f"{label:<7}: {code}, JOBS={jobs}: wall {used.wall_s:7.1f} s, CPU {used.cpu_s:7.1f} s "
            f"(user {used.user_s:.1f} + system {used.system_s:.1f}), {used.page_faults} page faults "
            f"(load average at start {load})"
        )
    before, after = results["before"], results["after"]
    print(
        f"ratio  : wall before/after {before.wall_s / after.wall_s:.2f}x, "
        f"CPU after/before {after.cpu_s / before.cpu_s:.2f}"
    )
    same = True
    for name in TABLES:
        table_before, table_after = (
            without_time_column(
                (args.out / label / f"{name}.txt").read_text(encoding="utf-8"), args.out / label
            )
            for label in ("before", "after")
        )
        if table_before != table_after:
            same = False
            print(
                f"tables : {name}: DIFFERENT (diff {args.out}/before/{name}.txt {args.out}/after/{name}.txt)"
            )
    if same:
        print(f"tables : the same to the printed digit ({', '.join(TABLES)}; fit times apart)")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
