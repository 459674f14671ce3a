"""``trainer fit --method M TRAIN -o model.pt``: fit one compensator and save its checkpoint."""

from __future__ import annotations

import argparse
from typing import Any

from trainer import methods

# Heavy modules (torch) are imported inside run() so that 'trainer --help' starts fast.


def add_parser(subparsers: Any) -> None:
    parser = subparsers.add_parser("fit", help="fit a compensator on a training recording")
    parser.add_argument("train", help="training recording (.csv or .npz)")
    parser.add_argument(
        "--method", required=True, choices=methods.fit_cli_names(), help="compensation method"
    )
    parser.add_argument("-o", "--output", required=True, help="checkpoint to write (model.pt)")
    groups = []  # each method's options once, however many methods share them
    for method in methods.entries():
        if method.in_fit_cli and method.options not in groups:
            groups.append(method.options)
            method.options.add_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from trainer.checkpoint import save_model
    from trainer.data.recording_io import read_recording
    from trainer.errors import check_output_path
    from trainer.fitting import fit_compensator, training_stats

    check_output_path(args.output)  # fail before a long training run, not after it
    options = methods.get(args.method).options.fit_kwargs(args)
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
    for line in model.describe():
        print(line)
    return 0
