"""``trainer fit --method M TRAIN -o model.pt``: fit one compensator and save its checkpoint."""

from __future__ import annotations

import argparse
from typing import Any

from trainer.commands.dlstm_options import add_dlstm_options, settings_from_args

# Heavy modules (torch) are imported inside run() so that 'trainer --help' starts fast.
METHODS = ("pla", "poly3", "dlstm", "dlstm-ssa", "dlstm-issa", "dlstm-temp")
DLSTM_METHODS = ("dlstm", "dlstm-ssa", "dlstm-issa", "dlstm-temp")


def add_parser(subparsers: Any) -> None:
    parser = subparsers.add_parser("fit", help="fit a compensator on a training recording")
    parser.add_argument("train", help="training recording (.csv or .npz)")
    parser.add_argument("--method", required=True, choices=METHODS, help="compensation method")
    parser.add_argument("-o", "--output", required=True, help="checkpoint to write (model.pt)")
    parser.add_argument("--intervals", type=int, default=10, help="pla: number of temperature intervals (10)")
    parser.add_argument(
        "--remove-median",
        action="store_true",
        help="poly3: subtract the axis median first, exactly as PX4 does (offset left to "
        "the six-position calibration)",
    )
    add_dlstm_options(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from trainer.checkpoint import save_model
    from trainer.data.recording_io import read_recording
    from trainer.errors import check_writable
    from trainer.fitting import fit_compensator, training_stats

    check_writable(args.output)  # fail before a long training run, not after it
    options: dict[str, Any] = {}
    if args.method == "pla":
        options["n_intervals"] = args.intervals
    elif args.method == "poly3":
        options["remove_median"] = args.remove_median
    else:
        settings, frontend = settings_from_args(args)
        options = {"settings": settings, "frontend_seconds": frontend, "progress": not args.quiet}
    train = read_recording(args.train)
    model = fit_compensator(args.method, train, options)
    stats = training_stats(train)
    residual = train.accel_mg - model.predict_drift(train.without_truth())
    stats["fit_residual_rms_mg"] = float(np.sqrt(np.mean((residual - residual.mean()) ** 2)))
    save_model(
        model, args.output, train_stats=stats, valid_temp_range_c=(stats["temp_min_c"], stats["temp_max_c"])
    )
    print(
        f"{args.method}: fitted on {stats['n_samples']} samples "
        f"({stats['temp_min_c']:.2f} .. {stats['temp_max_c']:.2f} degC), "
        f"fit residual RMS {stats['fit_residual_rms_mg']:.4g} mg -> {args.output}"
    )
    return 0
