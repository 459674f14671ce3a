"""Could another of auto's candidates rescue the splits auto loses? (issue 20)

bench/bench_real_splits.py scores ``--method auto`` trained on part of the bundled run at 14 splits
per channel; on parts of less than a cycle it chooses between the cubic and no compensation, and
loses to the other at 22 of 84 channel-splits. This bench asks two questions of every candidate,
scored on the held-out part as bench_real_splits scores it (cold when it starts the run, warm
otherwise), counted where it is within 2 % of the better of (cubic, none):

1. **Shipped whatever the part says**: each candidate fitted on the training part
   (``trainer fit --method LABEL --holdout SPEC`` reproduces any cell).
2. **Chosen by the part's own cross-validation** on the parts of less than a cycle, among none,
   poly1, poly2, the cubic and PLA (the quick candidates): the lowest pooled figure, the lowest in
   range, or the smallest worst ratio to the better of (cubic, none) over the part's segments; and
   how many of those parts any of the five would have rescued.

    .venv/bin/python bench/bench_split_candidates.py [--physics] [--markdown out.md]

``--physics`` adds physics-branch-room and physics-branches to the first question (minutes).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

from bench_real_splits import SPLITS, held_out_rms
from bundled_run import bundled_run

from trainer import methods
from trainer.data.channels import channel_view, select_channels
from trainer.data.holdout import parse_holdout, split
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.fitting import fit_compensator
from trainer.scoring.crossval import CrossValidation, cross_validate
from trainer.selection import (
    NONE,
    TOLERANCE,
    candidate,
    full_cycle,
    leaves_more_than_none,
    row_name,
    worst_ratio,
)

QUICK = (NONE, "poly1", "poly2", methods.CUBIC, methods.PLA)  # cross-validated in seconds per part
PHYSICS = (f"{methods.PHYSICS}-branch-room", f"{methods.PHYSICS}-branches")

# how a rule reads the part's cross-validation: the figure it minimises over the allowed candidates
RULES: dict[str, Callable[[CrossValidation, str], float]] = {
    "lowest pooled": lambda cv, label: cv.results[row_name(label)].cv_rms,
    "lowest in range": lambda cv, label: cv.results[row_name(label)].cv_in_range_rms,
    "smallest worst ratio": worst_ratio,
}


def fitter(label: str) -> Callable[[object], object]:
    chosen = candidate(label)
    return lambda train: fit_compensator(chosen.method, train, dict(chosen.options))  # type: ignore[arg-type]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--physics", action="store_true", help="also fit physics-branch-room and -branches")
    parser.add_argument("--markdown", type=Path)
    args = parser.parse_args()
    shipped = QUICK + (PHYSICS if args.physics else ())
    rec = bundled_run()
    fixed = dict.fromkeys(shipped, 0)
    chosen = dict.fromkeys(RULES, 0)
    rescued = short = total = 0
    started = time.perf_counter()
    for channel in select_channels(rec, ("all",)):
        view = channel_view(rec, channel)
        for spec in SPLITS:
            holdout = parse_holdout(spec)
            train, held = split(view, holdout)
            start, stop = (0, len(held)) if holdout.side == "first" else (len(train), len(view))
            scores = {
                label: held_out_rms(None if label == NONE else fitter(label)(train), view, start, stop)
                for label in shipped
            }
            better = min(scores[NONE], scores[methods.CUBIC]) * (1.0 + TOLERANCE)
            total += 1
            for label in shipped:
                fixed[label] += scores[label] <= better
            cv = cross_validate(
                train,
                {label: fitter(label) for label in QUICK if label != NONE},
                stateful=set(),
                smoothing_s=PAPER_RUN_SMOOTHING_S,
            )
            if full_cycle(cv.segments):
                continue  # auto judges every candidate there
            short += 1
            allowed = [x for x in QUICK if not leaves_more_than_none(cv, x)]
            for name, figure in RULES.items():
                pick = min(allowed, key=lambda x, f=figure: f(cv, x))  # type: ignore[misc]
                chosen[name] += scores[pick] <= better
            rescued += any(scores[x] <= better for x in QUICK)
            print(
                f"{channel.name} {spec}: " + ", ".join(f"{k} {v:.4g}" for k, v in scores.items()), flush=True
            )
    out = [
        f"machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}; "
        f"{time.perf_counter() - started:.0f} s",
        "",
        f"Shipped at every split whatever the part says (within {100 * TOLERANCE:g} % of the better of "
        f"(cubic, none) held out, of {total} channel-splits):",
        "",
        "| candidate | splits |",
        "|---|---|",
        *[f"| {label} | {n} |" for label, n in fixed.items()],
        "",
        f"Chosen among {', '.join(QUICK)} by the part's own cross-validation, on the {short} parts of less "
        "than a cycle:",
        "",
        "| rule | splits |",
        "|---|---|",
        *[f"| {name} | {n} |" for name, n in chosen.items()],
        f"| any of the five (known only held out) | {rescued} |",
    ]
    print("\n".join(out))
    if args.markdown:
        args.markdown.write_text("\n".join(out) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
