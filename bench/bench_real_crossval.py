"""``--method auto`` on every channel of the bundled real run, cross-validated over its segments.

The recording (``shared/data/real/``, one 71 min cycle 51.6 -> -17.6 -> 74.0 -> 36.3 degC at
1.98 Hz, static; 3 accelerometer axes in mg, 3 gyroscope axes in deg/s) is imported with all its
channels as ``trainer import --preset tofupilot --channels all`` does. For each channel every
candidate of :mod:`trainer.selection` is cross-validated over the three thermal segments (cooling,
heating, cooling; each held out in turn, trained on the other two), exactly as ``trainer fit
--method auto`` does, and the table is printed with the choice, each candidate's per-segment
figures at their natural start (cold for the first segment, warm after), warm and cold medians,
and the mean fit time per fold on this machine.

The last block checks the issue-20 targets: auto within 2 % of the better of (cubic,
uncompensated) or better on every segment, warm and cold; physics against the cubic (median); and
physics from power-on: its worst segment started cold against the cubic's on that segment (a cold
start knows none of the history states: lag and rate filters start settled, the branch half-way).

``--recording`` runs the same on another recording, such as the main job's simulated
``realistic-train.npz`` (its channels, or its ``accel_mg`` with ``--channels accel_mg``).

    python bench/bench_real_crossval.py [--channels accel0_z,gyro0_x] [--markdown table.md]
    python bench/bench_real_crossval.py --recording out/realistic-train.npz --channels accel_mg
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
from bundled_run import bundled_run

from trainer import methods
from trainer.data.channels import ONE_AXIS_CHANNEL, channel_view, select_channels
from trainer.data.recording_io import read_recording
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.scoring.crossval import UNCOMPENSATED
from trainer.selection import row_name, select, ship


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--channels", default="all")
    parser.add_argument("--recording", type=Path, help="a recording instead of the bundled real run")
    parser.add_argument("--markdown", type=Path)
    args = parser.parse_args()
    rec = bundled_run() if args.recording is None else read_recording(args.recording)
    wanted = tuple(args.channels.split(",")) if args.channels != "all" else ("all",)
    out = [f"machine: {platform.processor() or platform.machine()}, {platform.python_version()}", ""]
    checks: list[str] = []
    views = (
        [(ONE_AXIS_CHANNEL, rec, "mg")]
        if wanted == (ONE_AXIS_CHANNEL,)
        else [(c.name, channel_view(rec, c), c.label) for c in select_channels(rec, wanted)]
    )
    for name, view, label in views:
        start = time.perf_counter()
        selection = select(view, smoothing_s=PAPER_RUN_SMOOTHING_S, unit=label)
        seconds = time.perf_counter() - start
        _, _, selection = ship(selection, view)  # what auto ships: its fit on the whole run checked
        cv = selection.cv
        first = len(out)
        out += [f"## {name} ({label}): auto chose {selection.chosen} ({seconds:.0f} s)", ""]
        out += selection.table()
        out += ["", f"auto: chose {selection.chosen}: {selection.reason}"]
        out += [
            "",
            "fit time per fold (s): "
            + ", ".join(f"{n} {r.fit_seconds:.1f}" for n, r in cv.results.items() if n != UNCOMPENSATED),
            "",
        ]
        chosen = row_name(selection.chosen)
        raw, cubic, auto = cv.results[UNCOMPENSATED], cv.results[methods.CUBIC], cv.results[chosen]
        for mode in ("warm_rms", "cold_rms"):
            ref = np.minimum([getattr(f, mode) for f in raw.folds], [getattr(f, mode) for f in cubic.folds])
            mine = np.array([getattr(f, mode) for f in auto.folds])
            worst = float(np.max(mine / ref - 1.0))
            checks.append(
                f"{name} {mode[:4]}: auto vs better of (cubic, none), worst segment {100 * worst:+.1f} % "
                f"({'met' if worst <= 0.02 else 'NOT met'})"
            )
        folds = list(zip(cv.results[methods.PHYSICS].folds, cubic.folds, strict=True))
        cold = [f.cold_rms / c.cold_rms - 1.0 for f, c in folds]
        at = int(np.argmax(cold))
        warm = folds[at][0].warm_rms / folds[at][1].warm_rms - 1.0
        checks.append(
            f"{name}: physics from power-on (every segment started cold) against the cubic there, worst segment "
            f"{100 * cold[at]:+.1f} % (segment {at + 1}; started warm {100 * warm:+.1f} %)"
        )
        physics = np.median(cv.results[methods.PHYSICS].natural()) / np.median(cubic.natural()) - 1.0
        auto_vs_cubic = np.median(auto.natural()) / np.median(cubic.natural()) - 1.0
        checks.append(
            f"{name}: median over segments, physics {100 * physics:+.1f} % and auto {100 * auto_vs_cubic:+.1f} % "
            "against the cubic"
        )
        print("\n".join(out[first:]), flush=True)
    out += ["## Targets", "", *[f"- {c}" for c in checks]]
    text = "\n".join(out)
    print("\n".join(["", "## Targets", *checks]))
    if args.markdown:
        args.markdown.write_text(text + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
