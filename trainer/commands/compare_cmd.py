"""``trainer compare TRAIN VALID``: every method, the paper's Table 1, honest scores, figures, report."""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from trainer import methods
from trainer.data.channels import Channel, method_refusal
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.errors import UserError, current_umask, raise_write_error
from trainer.options.channels import PREFIX_ATTR, add_channels_option, run_per_channel
from trainer.options.dlstm import add_dlstm_options, settings_from_args
from trainer.options.numbers import MAX_SECONDS, check_finite
from trainer.options.offset import add_offset_options, policy_from_args
from trainer.options.workers import workers
from trainer.physics.input_presets import INPUT_PRESETS
from trainer.report_dir import check_report_dir, previous_outputs, record_outputs, remove_stale

# Heavy modules (torch, matplotlib) are imported inside run() so that 'trainer --help' starts fast.


def add_parser(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "compare", help="train every method, score them like the paper's Table 1 and write a report"
    )
    parser.add_argument("train", help="training recording (.csv or .npz); with --holdout, the one recording")
    parser.add_argument(
        "valid",
        nargs="?",
        help="validation recording (.csv or .npz); without it and without --holdout, TRAIN is cross-validated over its thermal segments",
    )
    parser.add_argument(
        "--holdout",
        metavar="SPEC",
        help="score on a held-out part of TRAIN and train on the rest: F or last:F (the last fraction F), "
        "first:F, or T0: / :T1 in seconds (docs/real-data.md)",
    )
    parser.add_argument(
        "--inject",
        choices=INPUT_PRESETS,
        help="add this known input (steps: up to 50 in the channel's unit: tilts of 50 mg, 50 deg/s of rotation on a gyroscope) to the validation data and report how "
        "much of it each method keeps",
    )
    parser.add_argument(
        "--out-dir", default="comparison", help="report, figures and models go here (comparison/)"
    )
    parser.add_argument(
        "--input-test",
        action="append",
        default=[],
        metavar="REC",
        help="a recording with a true input (true_accel_mg), to measure how much of it each method keeps; "
        "repeatable",
    )
    parser.add_argument(
        "--methods",
        default=",".join(methods.names()),
        help=f"comma-separated subset of {','.join(methods.names())}",
    )
    parser.add_argument(
        "--smoothing",
        type=float,
        default=PAPER_RUN_SMOOTHING_S,
        help="validation smoothing in s (paper: 0.5)",
    )
    parser.add_argument(
        "--jobs",
        type=workers,
        metavar="N",
        help="fit in N worker processes, with the same results as 1: a cross-validation's fits (one thread "
        "each; default one per core), or with VALID or --holdout the methods side by side (--threads torch "
        "threads each; default 1)",
    )
    add_dlstm_options(parser)
    add_offset_options(parser)
    add_channels_option(parser, "compare the methods on the channel, report in OUT/<channel>")
    parser.set_defaults(func=run)


def _refusal(args: argparse.Namespace) -> Callable[[Channel], str | None]:
    """A recursive method in --methods on a barometer channel is refused (trainer.data.channels)."""
    requested = [m.strip() for m in args.methods.split(",") if m.strip() in methods.REGISTRY]

    def refuse(channel: Channel) -> str | None:
        for name in requested:
            reason = method_refusal(name, methods.get(name).family, channel)
            if reason is not None:
                return f"{reason}; leave it out of --methods"
        return None

    return refuse


def publish(staging: Path, out_dir: Path, command: str) -> None:
    """Move a finished report of ``command`` into ``out_dir``: a rename when it is new, else file by file.

    Existing files of the same names are replaced, and the files the same command's earlier report
    there wrote and this one does not are removed (:mod:`trainer.report_dir`); the user's files stay.
    """
    written = [p.relative_to(staging).as_posix() for p in staging.rglob("*") if p.is_file()]
    previous = previous_outputs(out_dir, command)
    record_outputs(staging, command, written)
    if not out_dir.exists():
        # mkdtemp made it 0700: a new report directory gets the usual mode (a reviewer reads it)
        os.chmod(staging, 0o777 & ~current_umask())
        staging.rename(out_dir)
        return
    for source in sorted(staging.rglob("*")):
        if source.is_file():
            target = out_dir / source.relative_to(staging)
            target.parent.mkdir(parents=True, exist_ok=True)
            source.replace(target)
    shutil.rmtree(staging)
    if removed := remove_stale(out_dir, previous, written):
        print(
            f"{out_dir}: removed {len(removed)} file(s) of the earlier {command} report this one does not write: "
            + ", ".join(removed),
            file=sys.stderr,
            flush=True,
        )


def run(args: argparse.Namespace) -> int:
    if args.channels is not None:
        if args.input_test:
            raise UserError("--input-test (a simulated true input on accel_mg) applies without --channels")
        return run_per_channel(
            args, run, recordings=("train", "valid"), out_dirs=("out_dir",), refuse=_refusal(args)
        )
    known = methods.names()
    requested = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    unknown = [m for m in requested if m not in known]
    if unknown or not requested:
        raise UserError(
            f"--methods: unknown {', '.join(unknown) or '(empty)'}; choose from {','.join(known)}"
        )
    check_finite("--smoothing", args.smoothing, maximum=MAX_SECONDS)
    settings, frontend = settings_from_args(args)
    for name in requested:  # before any fit: a search over one network failed after the training
        if (optimiser := getattr(methods.get(name).cls, "optimiser", None)) is not None:
            from trainer.dlstm.compensators import check_search_population

            check_search_population(optimiser, settings.population)
    policy = policy_from_args(args)
    if args.valid is not None and args.holdout is not None:
        raise UserError("compare: give a validation recording VALID or --holdout SPEC, not both")
    if args.valid is None and args.holdout is None:
        return run_crossval(args, requested, policy)

    from trainer.checkpoint import save_model
    from trainer.data.channels import relabel_units, signal_of
    from trainer.data.holdout import overlap_warning, parse_holdout, split
    from trainer.data.plausibility import WIDER_RUN_HINT, check_scored
    from trainer.data.recording import data_fingerprint
    from trainer.data.recording_io import read_recording
    from trainer.fitting import training_stats
    from trainer.scoring.compare import compare
    from trainer.scoring.report import headline_table, render_report, write_figures, write_survival_figure

    out_dir = Path(args.out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"--out-dir {out_dir}: exists and is not a directory")
    check_report_dir(out_dir, "compare")
    notes = []
    lead_in = None
    if args.holdout is not None:
        holdout = parse_holdout(args.holdout)
        train, valid = split(check_scored(read_recording(args.train)), holdout)
        t0_s = float(min(train.time_s[0], valid.time_s[0]))  # logger clocks (Unix time) read from the start
        notes.append(
            f"one recording, {holdout.describe()}: training t = {train.time_s[0] - t0_s:g} .. "
            f"{train.time_s[-1] - t0_s:g} s, validation t = {valid.time_s[0] - t0_s:g} .. "
            f"{valid.time_s[-1] - t0_s:g} s from the recording's start"
        )
        if holdout.side == "last":
            lead_in = train.without_truth()
            notes.append(
                "the validation part follows the training part: every method runs through the training part "
                "first (as firmware running since power-on) and is scored on the validation part only"
            )
    else:
        train = check_scored(read_recording(args.train))
        valid = check_scored(read_recording(args.valid))
    too_short = short_span_methods(train, requested)
    if too_short and len(too_short) == len(requested):
        raise UserError(f"{train.source}: compare: {all_too_short(train, requested)}: {WIDER_RUN_HINT}")
    requested = tuple(m for m in requested if m not in too_short)
    notes += [f"{name}: not compared ({why})" for name, why in too_short.items()]
    for name, why in too_short.items():
        print(f"{train.source}: {name} not compared: {why}", file=sys.stderr, flush=True)
    warning = overlap_warning(training_stats(train), valid, data_fingerprint(valid))
    if warning:
        print(warning, file=sys.stderr, flush=True)
        notes.append(f"**{warning}**")
    input_tests = tuple(check_scored(read_recording(path)) for path in args.input_test)
    for rec in input_tests:
        if rec.truth("accel_mg") is None:
            raise UserError(f"{rec.source}: --input-test needs a true_accel_mg column (a simulated input)")

    def log(message: str) -> None:
        print(f"{getattr(args, PREFIX_ATTR, '')}{message}", file=sys.stderr, flush=True)

    comparison = compare(
        train,
        valid,
        settings,
        input_tests=input_tests,
        smoothing_s=args.smoothing,
        methods=requested,
        progress=not args.quiet,
        log=log,
        policy=policy,
        inject=args.inject,
        lead_in=lead_in,
        jobs=args.jobs or 1,
    )
    comparison.notes += notes
    signal = signal_of(valid)
    table1 = relabel_units(f"{signal.heading}\n{comparison.evaluation.table.to_text()}", signal.unit)
    # Everything is written into a fresh directory first and moved into place at the end, so a
    # failure never leaves a half-written report.
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    try:
        (staging / "models").mkdir()
        stats = training_stats(train)
        for name, model in comparison.models.items():
            save_model(
                model,
                staging / "models" / f"{name}.pt",
                train_stats=stats,
                valid_temp_range_c=stats.temp_range_c,
            )
        figures = write_figures(comparison, train, valid, staging)
        for index, rec in enumerate(input_tests):
            name = f"fig_input_survival_{index + 1}_{Path(rec.source).stem}.png"
            write_survival_figure(comparison, rec, staging, name)
            figures.append(name)
        report = render_report(comparison, settings, frontend, args, figures, signal.heading, signal.unit)
        (staging / "report.md").write_text(relabel_units(report, signal.unit), encoding="utf-8")
        (staging / "table1.txt").write_text(table1 + "\n", encoding="utf-8")
        publish(staging, out_dir, "compare")
    except BaseException as exc:
        shutil.rmtree(staging, ignore_errors=True)
        raise_write_error(exc, out_dir)
        raise
    print(table1)
    print()
    print(relabel_units(headline_table(comparison), signal.unit))
    print(f"\nreport, figures and models written to {out_dir}/")
    return 0


def short_span_methods(train: Any, requested: Sequence[str]) -> dict[str, str]:
    """The requested methods the training temperature spans too little for, with the reason (as
    ``trainer fit`` refuses them: a shape in temperature the run cannot determine)."""
    from trainer.data.plausibility import span_shortfall

    out = {}
    for name in requested:
        if (why := span_shortfall(train.temp_c, name, methods.get(name).min_temp_span_c)) is not None:
            out[name] = why
    return out


def all_too_short(train: Any, names: Sequence[str]) -> str:
    """One reason for methods that all need more span than ``train`` has (the smallest need)."""
    from trainer.data.plausibility import span_shortfall

    need_c = min(methods.get(name).min_temp_span_c for name in names)
    return span_shortfall(train.temp_c, ", ".join(names), need_c) or ""


def run_crossval(args: argparse.Namespace, requested: tuple[str, ...], policy: Any) -> int:
    """One recording, no --holdout: blocked cross-validation over its thermal segments
    (:mod:`trainer.scoring.crossval`); recursive methods cannot be trained on a run with a hole."""
    import json

    from trainer.commands.selection_output import progress_log
    from trainer.data.channels import signal_of
    from trainer.data.plausibility import WIDER_RUN_HINT, check_scored
    from trainer.data.recording_io import read_recording
    from trainer.fitting import fit_compensator
    from trainer.options.workers import jobs_task_map
    from trainer.scoring.crossval import cross_validatable, cross_validate, segment_lines, table_lines

    if args.inject is not None or args.input_test:
        raise UserError(
            "compare: --inject and --input-test need VALID or --holdout (cross-validation scores drift)"
        )
    out_dir = Path(args.out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"--out-dir {out_dir}: exists and is not a directory")
    check_report_dir(out_dir, "compare")
    rec = check_scored(read_recording(args.train))
    signal = signal_of(rec)
    unit = signal.label
    settings, _ = settings_from_args(args)
    too_short = short_span_methods(rec, requested)
    chosen = [m for m in requested if cross_validatable(m) and m not in too_short]
    skipped = {
        m: too_short.get(m, "recursive: it cannot be trained on a run with a hole; score it with --holdout")
        for m in requested
        if m not in chosen
    }
    if not chosen and too_short:
        raise UserError(f"{rec.source}: compare: {all_too_short(rec, list(too_short))}: {WIDER_RUN_HINT}")
    if not chosen:
        raise UserError(
            f"compare: none of --methods {','.join(requested)} can be cross-validated; give --holdout"
        )

    def fitter(name: str) -> Callable[[Any], object]:
        kwargs = methods.get(name).options.compare_kwargs(settings, False)
        return lambda train: fit_compensator(name, train, kwargs, policy)

    with jobs_task_map(args.jobs) as tasks:
        cv = cross_validate(
            rec,
            {name: fitter(name) for name in chosen},
            stateful={m for m in chosen if methods.get(m).family == methods.TEMPERATURE_DRIVEN},
            smoothing_s=args.smoothing,
            unit=unit,
            log=progress_log(args, getattr(args, PREFIX_ATTR, "")),
            tasks=tasks,
        )
    cv.skipped.update(skipped)
    lines = [
        # a per-channel run's recording is named "FILE (channel NAME)" already (trainer.options.channels)
        f"# Cross-validated comparison: {rec.source}, "
        + (f"in {signal.label}" if getattr(args, PREFIX_ATTR, "") else f"channel {signal.heading}"),
        "",
        f"No validation recording and no --holdout: every thermal segment of the run is held out in turn, "
        f"each method trained on the rest (docs/real-data.md). Drift left: RMS of the compensated output about "
        f"its mean over the held-out segment, in {unit}.",
        "",
        *segment_lines(cv.segments),
        "",
        *table_lines(cv),
        "",
        *[f"- {name}: not cross-validated ({why})" for name, why in cv.skipped.items()],
    ]
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    try:
        (staging / "report.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
        (staging / "crossval.json").write_text(json.dumps(cv.to_dict(), indent=2) + "\n", encoding="utf-8")
        publish(staging, out_dir, "compare")
    except BaseException as exc:
        shutil.rmtree(staging, ignore_errors=True)
        raise_write_error(exc, out_dir)
        raise
    print("\n".join([*segment_lines(cv.segments), *table_lines(cv)]))
    print(f"\nreport and crossval.json written to {out_dir}/")
    return 0
