"""Does ``--method auto`` keep its verdict at any split of the bundled real run? (issue 20, item 6)

The cross-validation that chooses a channel's compensator (bench/bench_real_crossval.py) uses every
thermal segment of the run. A user holds out one part instead, at a split nobody chose for us. For
each split (``first:F`` and ``last:F`` for F = 0.2 .. 0.6, and time splits) and each of the six
channels, this bench runs ``trainer fit --method auto`` on the training part only (its own
cross-validation over the segments the part contains), fits the cubic on the same rows, and scores
both and the uncompensated channel on the held-out part: the static drift left (RMS of the output
about its branch means, smoothed as the paper's run), in the channel's unit. A held-out part that
starts the run starts cold (power-on); one that follows training runs warm.

The verdict at a split: auto is within 2 % of the better of (cubic, uncompensated), or better.

    .venv/bin/python bench/bench_real_splits.py [--channels accel0_z_mg,...] [--markdown out.md]
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
from trainer.data.channels import channel_view, select_channels
from trainer.data.holdout import parse_holdout, split
from trainer.data.recording import Recording
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.fitting import fit_compensator
from trainer.scoring.evaluate import smooth_for_scoring
from trainer.scoring.static import static_drift_left, thermal_branch
from trainer.selection import AUTO, TOLERANCE, candidate_list, fit_with_selection

FRACTION_SPLITS = tuple(f"{side}:{f / 10:g}" for side in ("first", "last") for f in range(2, 7))
SPLITS = (*FRACTION_SPLITS, ":1500", "1500:", ":3000", "3000:")  # time splits, seconds from the start


def held_out_rms(model: object | None, rec: Recording, held_start: int, held_stop: int) -> float:
    """Drift left on rows [held_start, held_stop) of ``rec``: the model runs from the recording's
    start (warm) when training precedes, from the held-out part's start (cold) when it starts the run."""
    rate = rec.sample_rate_hz
    part = rec if held_start > 0 else rec.slice(0, held_stop)
    output = part.accel_mg if model is None else part.accel_mg - model.predict_drift(part)  # type: ignore[attr-defined]
    smoothed = smooth_for_scoring(np.asarray(output, dtype=np.float64), rate, PAPER_RUN_SMOOTHING_S)
    temp = np.asarray(rec.temp_c, dtype=np.float64)
    branch = thermal_branch(temp, rate)[held_start:held_stop]
    return float(static_drift_left(np.asarray(smoothed)[held_start:held_stop], branch).rms_mg)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--channels", default="all")
    parser.add_argument("--splits", default=",".join(SPLITS))
    parser.add_argument("--candidates", type=candidate_list, help="auto's candidates (default all)")
    parser.add_argument("--markdown", type=Path)
    args = parser.parse_args()
    rec = bundled_run()
    wanted = tuple(args.channels.split(",")) if args.channels != "all" else ("all",)
    specs = [s for s in args.splits.split(",") if s]
    out = [f"machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}", ""]
    tally: list[str] = []
    for channel in select_channels(rec, wanted):
        view = channel_view(rec, channel)
        out += [
            f"## {channel.name} ({channel.label})",
            "",
            "| held out | start | uncompensated | cubic | auto | auto chose | auto vs better of (cubic, none) | fit s |",
            "|---|---|---|---|---|---|---|---|",
        ]
        met = 0
        for spec in specs:
            holdout = parse_holdout(spec)
            train, held = split(view, holdout)
            first = holdout.side == "first"
            start, stop = (0, len(held)) if first else (len(train), len(view))
            clock = time.perf_counter()
            auto, stats = fit_with_selection(AUTO, train, {"candidates": args.candidates})
            seconds = time.perf_counter() - clock
            cubic = fit_compensator(methods.CUBIC, train)
            raw = held_out_rms(None, view, start, stop)
            cub = held_out_rms(cubic, view, start, stop)
            mine = held_out_rms(auto, view, start, stop)
            gap = mine / min(raw, cub) - 1.0
            met += gap <= TOLERANCE
            out.append(
                f"| `{spec}` | {'cold' if first else 'warm'} | {raw:.4g} | {cub:.4g} | {mine:.4g} | "
                f"{(stats.selection or {}).get('chosen')} | {100 * gap:+.1f} % | {seconds:.0f} |"
            )
            print(out[-1], flush=True)
        tally.append(
            f"{channel.name}: auto within {100 * TOLERANCE:g} % of the better of (cubic, none) at {met} of {len(specs)} splits"
        )
        out.append("")
    out += ["## Verdict at every split", "", *[f"- {t}" for t in tally]]
    print("\n".join(tally))
    if args.markdown:
        args.markdown.write_text("\n".join(out) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
