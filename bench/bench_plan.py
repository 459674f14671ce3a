"""`trainer plan` bench: the planned program against the standard profiles (docs/plan.md's table).

Runs ``trainer plan`` with the default targets (lag, rate and branch offset of the bundled run's
sizes) and chamber (-20..70 degC, 2 degC/min, 20 min settling) for a 6 h limit, with the standard
profiles' rows, then for a 3 h limit: when the 6 h design already lasts at most 3 h, the 3 h search
tries the same candidates in the same order with the same seeded draws, so its answer is the same
and is not recomputed. Each report lands in OUT/plan-<hours>h/report.md.

    python bench/bench_plan.py [OUT] [--draws N] [--workers N]

``--candidates I,J`` skips the search: the Monte Carlo of candidates I, J (indices into the 6 h
list, shortest first, as the report's "Candidates tried") beside the standard profiles, one table
in OUT/candidates.md (what the search would reach only after screening the shorter ones).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from trainer.cli import main
from trainer.plan import outputs

SEED = 1


def plan(out: Path, hours: float, draws: int, workers: int, standard: bool) -> str:
    argv = ["plan", "-o", str(out), "--max-hours", str(hours), "--draws", str(draws)]
    argv += ["--workers", str(workers), "--seed", str(SEED)] + ([] if standard else ["--no-standard"])
    start = time.perf_counter()
    main(argv)
    print(f"({hours:g} h limit: {time.perf_counter() - start:.0f} s)")
    return (out / outputs.REPORT_MD).read_text(encoding="utf-8")


def table_of(out: Path, indices: list[int], draws: int, workers: int) -> None:
    """The Monte Carlo table of chosen candidates and the standard profiles (no search)."""
    from dataclasses import replace
    from importlib import resources

    from trainer.commands.plan_cmd import DEFAULT_RATE_HZ, SENSOR_CONFIG
    from trainer.physics.config import load_config
    from trainer.plan import priors
    from trainer.plan.chamber import validation_program
    from trainer.plan.limits import ChamberLimits
    from trainer.plan.montecarlo import DrawTask, runner
    from trainer.plan.programs import candidates, standard
    from trainer.plan.summary import Target, summarise

    limits, target, targets = ChamberLimits(), Target(), priors.bundled()
    base = replace(load_config(str(resources.files("trainer.physics").joinpath(SENSOR_CONFIG))), channels=())
    validation = validation_program(limits)
    options = candidates(limits)
    programs = [options[i] for i in indices] + list(standard(limits))
    start = time.perf_counter()
    with runner(workers, None, True) as pool:
        rows = [
            summarise(
                p.name,
                p.duration_s,
                pool.map(
                    [DrawTask(base, targets, p, validation, SEED, i, DEFAULT_RATE_HZ) for i in range(draws)],
                    p.name,
                ),
                targets,
                target,
            )
            for p in programs
        ]
    text = outputs.table(rows, targets, target)
    out.mkdir(parents=True, exist_ok=True)
    (out / "candidates.md").write_text(
        f"{draws} draws per profile, seed {SEED}, 1 Hz, {time.perf_counter() - start:.0f} s\n\n{text}\n",
        encoding="utf-8",
    )
    print(text)


def main_bench() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="out/bench_plan")
    parser.add_argument("--draws", type=int, default=20)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--candidates", help="comma-separated candidate indices: their table, no search")
    args = parser.parse_args()
    root = Path(args.out)
    if args.candidates:
        table_of(root, [int(i) for i in args.candidates.split(",")], args.draws, args.workers)
        return
    root.mkdir(parents=True, exist_ok=True)
    six = plan(root / "plan-6h", 6.0, args.draws, args.workers, standard=True)
    chosen_hours = float(six.split("**Planned: ", 1)[1].split(" h**", 1)[0].rsplit(", ", 1)[1])
    if chosen_hours <= 3.0:
        print(f"3 h limit: the 6 h design lasts {chosen_hours:.2f} h, so the 3 h search chooses the same")
    else:
        plan(root / "plan-3h", 3.0, args.draws, args.workers, standard=False)


if __name__ == "__main__":
    main_bench()
