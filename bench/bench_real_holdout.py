"""Every cheap method on the bundled real chamber run, held out both ways, on x, y and z.

The recording (``shared/data/real/``, one 71 min cycle 51.6 -> -17.6 -> 74.0 -> 36.3 degC at
1.98 Hz, static) is imported per axis exactly as ``trainer import --preset tofupilot --accel
imu.acc.X`` does, then ``trainer compare``'s own functions score every method on a held-out part:

- ``last:0.5`` / ``first:0.5``: train on the first half, score the second, and the other way round
  (the issue's "both ways round"; part of each held-out half lies outside the training range);
- ``3131:`` / ``:1361``: split at the temperature maximum (t = 3131 s) and minimum (t = 1361 s),
  so that the scored part lies inside the training range (train on cycle + heating, score the last
  cooling; train on heating + cooling, score the first cooling).

Scores (docs/real-data.md): drift left = deviation of the compensated output from a constant
(RMS, max, heating and cooling RMS; and the RMS over the held-out samples inside the training
temperature range), the share of injected tilt steps kept, the noise floor, and each method's fit
time on the training part (wall clock, this machine). A held-out end part is scored with every
method's state run through the training part first (firmware running since power-on); a held-out
start part starts cold, as at power-on.

    python bench/bench_real_holdout.py            # the methods without DLSTM options
    python bench/bench_real_holdout.py --dlstm    # + the recursive and the temperature-input DLSTM
                                                  #   (population 4, 500 iterations, no sparrow cycles)
    python bench/bench_real_holdout.py --markdown table.md
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch
from bundled_run import REAL

from trainer import methods as registry
from trainer.data.holdout import parse_holdout, split
from trainer.data.importer import import_foreign, options_with_preset
from trainer.dlstm.fusion import FusionSettings
from trainer.options.methods import DLSTM_OPTIONS
from trainer.scoring.compare import compare
from trainer.scoring.markdown import markdown_table

SPLITS = ("last:0.5", "first:0.5", "3131:", ":1361")
DLSTM_SETTINGS = FusionSettings(population=4, iterations=500, cycles=0)


def _cell(value: float) -> str:
    return f"{value:.2f}" if value == value else "n/a"


def chosen_methods(with_dlstm: bool) -> tuple[str, ...]:
    """Every method without DLSTM options (the cheap ones, ``physics`` included once registered);
    with ``with_dlstm`` also the first population-sharing DLSTM and the non-sharing DLSTMs (with no
    sparrow cycles the SSA/ISSA variants equal the first)."""
    chosen: list[str] = []
    shared = False
    for method in registry.entries():
        if method.options is not DLSTM_OPTIONS:
            chosen.append(method.name)
        elif with_dlstm and not (method.shares_population and shared):
            chosen.append(method.name)
            shared = shared or method.shares_population
    return tuple(chosen)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--recording", default=str(REAL), help="the tofupilot .tsv file")
    parser.add_argument("--dlstm", action="store_true", help="add dlstm and dlstm-temp (reduced settings)")
    parser.add_argument("--markdown", help="also write the table to this file")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)  # the fastest for these sizes (docs/trainer.md), and fair to other jobs
    methods = chosen_methods(args.dlstm)
    header = ["axis", "held out", "method", "drift left RMS (mg)", "max (mg)", "heating RMS (mg)"]
    header += ["cooling RMS (mg)", "steps kept (%)", "outside training range (%)", "noise floor (mg)"]
    header += ["in-range RMS (mg)", "fit time (s)"]
    rows = []
    for axis in "xyz":
        rec = import_foreign(args.recording, options_with_preset("tofupilot", accel=f"imu.acc.{axis}"))
        for holdout in SPLITS:
            spec = parse_holdout(holdout)
            train, valid = split(rec, spec)
            start = time.perf_counter()
            result = compare(
                train,
                valid,
                DLSTM_SETTINGS,
                methods=methods,
                progress=False,
                log=lambda _: None,
                inject="steps",
                lead_in=train if spec.side == "last" else None,
            )
            evaluation = result.evaluation
            kept = result.survival["injected-steps"]
            print(f"{axis} {holdout}: {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)
            for name in ("raw", *methods):
                left = evaluation.drift_left(name)
                assert left is not None
                outside = evaluation.out_of_range_fraction.get(name)
                rows.append(
                    [
                        axis,
                        holdout,
                        "uncompensated" if name == "raw" else name,
                        _cell(left.rms_mg),
                        _cell(left.max_abs_mg),
                        _cell(left.heating_rms_mg),
                        _cell(left.cooling_rms_mg),
                        "100" if name == "raw" else f"{100 * kept[name].gain:.1f}",
                        "" if outside is None else f"{100 * outside:.0f}",
                        _cell(evaluation.noise_floor_mg),
                        _cell(evaluation.static_in_range[name].rms_mg)
                        if name in evaluation.static_in_range
                        else "",
                        "" if name == "raw" else f"{result.fit_seconds[name]:.1f}",
                    ]
                )
    table = markdown_table(header, rows)
    print(table)
    if args.markdown:
        Path(args.markdown).write_text(table + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
