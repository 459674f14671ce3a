"""``trainer fit --method M TRAIN -o model.pt``: fit one compensator and save its checkpoint."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from trainer import methods
from trainer.commands.selection_output import (
    checked_method,
    print_fitted,
    print_held_out,
    print_selection,
    progress_log,
)
from trainer.options.channels import add_channels_option
from trainer.options.methods import NO_OPTIONS, OptionGroup, option_defaults, options_not_applying
from trainer.options.offset import add_offset_options, policy_from_args
from trainer.options.workers import workers
from trainer.selection import AUTO, CANDIDATES, candidate, candidate_list, resolved, variant_labels

# Heavy modules (torch) are imported inside run() so that 'trainer --help' starts fast.


def add_parser(subparsers: Any) -> None:
    parser = subparsers.add_parser("fit", help="fit a compensator on a training recording")
    parser.add_argument("train", help="training recording (.csv or .npz)")
    parser.add_argument(
        "--method",
        required=True,
        choices=(*methods.fit_cli_names(), *variant_labels(), AUTO),
        help="compensation method; auto: per channel, the candidate (see --candidates) that cross-validation "
        "over the run's thermal segments says leaves the least drift (docs/real-data.md); an auto candidate "
        f"({','.join(variant_labels())}): that candidate alone, as auto would fit it",
    )
    parser.add_argument(
        "-o", "--output", required=True, help="checkpoint to write (model.pt); a directory with --channels"
    )
    parser.add_argument(
        "--candidates",
        type=candidate_list,
        metavar="LIST",
        help=f"auto: the candidates to cross-validate (default all: {','.join(c.label for c in CANDIDATES)})",
    )
    parser.add_argument(
        "--jobs",
        type=workers,
        metavar="N",
        help="auto: the cross-validation's physics fits in N worker processes, one thread each, with the "
        "same results for any N (default one per core)",
    )
    parser.add_argument(
        "--holdout",
        metavar="SPEC",
        help="train on the part of the recording this leaves (as 'trainer compare --holdout': F or last:F, "
        "first:F, T0: or :T1); 'trainer evaluate MODEL REC --holdout SPEC' then scores the rest",
    )
    add_channels_option(parser, "fit one model, written as OUT/<channel>.pt with OUT/channels.json,")
    parser.add_argument(
        "--accept-implausible",
        action="store_true",
        help="warn instead of refusing implausible rates, units or a too small temperature span",
    )
    groups = []  # each method's options once, however many methods share them
    for method in methods.entries():
        if method.in_fit_cli and method.options not in groups:
            groups.append(method.options)
            method.options.add_arguments(parser)
    add_offset_options(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from trainer.checkpoint import save_model
    from trainer.data.channels import channel_unit, other_channels_note
    from trainer.data.flightlog import refuse_flight_log_output
    from trainer.data.plausibility import check_training
    from trainer.data.recording_io import RECORDING_SUFFIXES, read_recording
    from trainer.errors import UserError, check_output_path
    from trainer.options.workers import jobs_task_map
    from trainer.selection import fit_with_selection

    for option, value in (("--candidates", args.candidates), ("--jobs", args.jobs)):
        if value is not None and args.method != AUTO:
            raise UserError(f"{option} applies to --method auto")
    base = resolved(args.method, None)[0]
    own = NO_OPTIONS if args.method == AUTO else methods.get(base).options
    every = [(m.name, m.options) for m in methods.entries() if m.in_fit_cli]
    if stray := options_not_applying(args, own, every):
        option, owners = next(iter(stray.items()))
        raise UserError(
            f"{option} does not apply to --method {args.method}: it is an option of {', '.join(owners)}"
            + (f" (likewise {', '.join(list(stray)[1:])})" if len(stray) > 1 else "")
            + "; leave it out, or choose that method"
        )
    options = {"candidates": args.candidates} if args.method == AUTO else own.fit_kwargs(args)
    if args.method in variant_labels():
        refuse_fixed(args, own)
    policy = policy_from_args(args)
    if args.holdout is not None:
        from trainer.data.holdout import parse_holdout

        parse_holdout(args.holdout)  # a bad one is refused before any reading
    if args.channels is not None:
        from trainer.commands.fit_channels import fit_channels

        return fit_channels(args, options, policy)
    check_output_path(args.output, inputs=[args.train])  # fail before a long training run, not after it
    refuse_flight_log_output(args.output)
    if Path(args.output).suffix.lower() in RECORDING_SUFFIXES:
        raise UserError(
            f"{args.output}: a recording's name ({Path(args.output).suffix}) for the model file; a model is "
            "written as .pt (arguments swapped? the recording comes first, -o names the model)"
        )
    from trainer.data.holdout import part_left_for_training

    whole = read_recording(args.train)
    train = part_left_for_training(whole, args.holdout)
    if (note := other_channels_note(train)) is not None:
        print(note, file=sys.stderr, flush=True)
    checks = check_training(train, checked_method(args.method), accept=args.accept_implausible)
    with jobs_task_map(args.jobs) as tasks:
        model, stats = fit_with_selection(
            args.method, train, options, policy, log=progress_log(args), tasks=tasks
        )
    from trainer.scoring.fit_holdout import with_held_out_score

    stats = with_held_out_score(model, stats, whole, args.holdout)
    checks.print_warnings()
    print_selection(stats)
    save_model(model, args.output, train_stats=stats, valid_temp_range_c=stats.temp_range_c)
    # a gyro or baro recording holds its own unit in the accel_mg column
    print_fitted(model, stats, str(args.output), channel_unit(train))
    print_held_out(stats, str(args.output), channel_unit(train))
    return 0


def refuse_fixed(args: argparse.Namespace, own: OptionGroup) -> None:
    """A variant fixes some of its method's options (``physics-branches`` its effects, and so the whole
    structure): an option the user gave for one of them is refused in one line."""
    from trainer.errors import UserError

    fixed = candidate(args.method).options
    given = [
        dest for dest, default in option_defaults(own).items() if getattr(args, dest, default) != default
    ]
    # every physics option chooses the structure (the effects, where they come from, the warm-up's)
    if clash := [dest for dest in given if dest in fixed or "effects" in fixed]:
        fixes = ", ".join(f"{k} {v}" for k, v in fixed.items() if k != "given_by")
        raise UserError(
            f"--{clash[0].replace('_', '-')} does not apply to --method {args.method}: it fixes {fixes}; "
            f"leave it out, or use --method {candidate(args.method).method}"
        )
