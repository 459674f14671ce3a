"""Could another rule choose better between the cubic and none on less than a cycle? (issue 20)

On a training part that holds less than a whole thermal cycle, ``--method auto`` chooses between the
cubic and no compensation: the cubic, unless its cross-validation over the part's segments finds it
worse than none (:func:`trainer.selection.choose`). At many splits of the bundled run that choice
loses to the other one held out (bench/bench_real_splits.py). This bench asks whether the loss is the
rule's or the data's: for every split whose training part is less than a cycle and every channel it
scores the held-out part (as bench_real_splits does) and counts the splits where each rule's choice
is within 2 % of the better of the two:

* ``auto``: the rule shipped (segment folds; the cubic unless it leaves more than none);
* ``cubic``: always the cubic;
* ``thirds``: the same guard on other folds, each segment cut into thirds in time (a fold then
  trains on both branches and interpolates, where a segment fold extrapolates to the other branch);
* ``agree``: splits where the part's own cross-validation ranks cubic and none as the held-out
  part does; at the others a rule that follows that cross-validation chooses the worse of the two.

    .venv/bin/python bench/bench_short_part_rules.py [--markdown out.md]
"""

from __future__ import annotations

import argparse
import itertools
import platform
import sys
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from bench_real_splits import SPLITS, held_out_rms  # noqa: E402  (the same splits and scoring)
from bundled_run import bundled_run  # noqa: E402

from trainer import methods  # noqa: E402
from trainer.data.channels import channel_view, select_channels  # noqa: E402
from trainer.data.holdout import parse_holdout, split  # noqa: E402
from trainer.data.recording import Recording  # noqa: E402
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S  # noqa: E402
from trainer.fitting import fit_compensator  # noqa: E402
from trainer.scoring.crossval import (  # noqa: E402
    UNCOMPENSATED,
    CrossValidation,
    Segment,
    cross_validate,
    folds_of,
)
from trainer.selection import NONE, TOLERANCE, choose, full_cycle  # noqa: E402

THIRDS = 3


def thirds_of_segments(rec: Recording) -> list[Segment]:
    """Each of the part's folds cut into :data:`THIRDS` equal parts in time."""
    out = []
    for s in folds_of(rec):
        edges = [s.start + round(k * (s.stop - s.start) / THIRDS) for k in range(THIRDS + 1)]
        out += [
            Segment(a, b, s.label, s.t0_s, s.t1_s, s.temp_from_c, s.temp_to_c)
            for a, b in itertools.pairwise(edges)
        ]
    return out


def cubic_cv(train: Recording, folds: list[Segment] | None) -> CrossValidation:
    def fit(r: Recording) -> object:
        return fit_compensator(methods.CUBIC, r)

    return cross_validate(
        train, {methods.CUBIC: fit}, stateful=set(), smoothing_s=PAPER_RUN_SMOOTHING_S, fold_segments=folds
    )


def cubic_is_better(cv: CrossValidation) -> bool:
    return bool(cv.results[methods.CUBIC].cv_rms < cv.results[UNCOMPENSATED].cv_rms)


RULES: dict[str, Callable[[CrossValidation, CrossValidation], bool]] = {  # True: the cubic is chosen
    "auto": lambda segment_cv, _: choose(segment_cv)[0] != NONE,
    "cubic": lambda *_: True,
    "thirds": lambda _, thirds_cv: choose(thirds_cv)[0] != NONE,
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--markdown", type=Path)
    args = parser.parse_args()
    rec = bundled_run()
    header = " | ".join(RULES)
    out = [
        f"machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}",
        "",
        f"| channel | splits | {header} | agree |",
        "|---|---|" + "---|" * (len(RULES) + 1),
    ]
    totals = dict.fromkeys([*RULES, "agree"], 0)
    count = 0
    for channel in select_channels(rec, ("all",)):
        view = channel_view(rec, channel)
        met = dict.fromkeys([*RULES, "agree"], 0)
        splits = 0
        for spec in SPLITS:
            holdout = parse_holdout(spec)
            train, held = split(view, holdout)
            segment_cv = cubic_cv(train, None)
            if full_cycle(segment_cv.segments):
                continue  # auto judges every candidate there: bench_real_splits scores it
            splits += 1
            start, stop = (0, len(held)) if holdout.side == "first" else (len(train), len(view))
            raw = held_out_rms(None, view, start, stop)
            cub = held_out_rms(fit_compensator(methods.CUBIC, train), view, start, stop)
            best = min(raw, cub)
            thirds_cv = cubic_cv(train, thirds_of_segments(train))
            for name, rule in RULES.items():
                met[name] += (cub if rule(segment_cv, thirds_cv) else raw) <= best * (1.0 + TOLERANCE)
            met["agree"] += cubic_is_better(segment_cv) == (cub < raw)
        out.append(f"| {channel.name} | {splits} | " + " | ".join(str(met[k]) for k in met) + " |")
        print(out[-1], flush=True)
        count += splits
        for k in totals:
            totals[k] += met[k]
    out.append(f"| all | {count} | " + " | ".join(str(totals[k]) for k in totals) + " |")
    print(out[-1])
    if args.markdown:
        args.markdown.write_text("\n".join(out) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
