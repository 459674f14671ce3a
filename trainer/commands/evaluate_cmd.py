"""``trainer evaluate model.pt VALID.csv``: compensate a recording and print the paper's Table 1."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.errors import atomic_outputs
from trainer.options.channels import add_channels_option, run_per_channel
from trainer.options.numbers import MAX_SECONDS, check_finite
from trainer.physics.input_presets import INPUT_PRESETS
from trainer.report_dir import check_report_dir, record_outputs

# Heavy modules (torch, matplotlib) are imported inside run() so that 'trainer --help' starts fast.


def add_parser(subparsers: Any) -> None:
    parser = subparsers.add_parser("evaluate", help="compensate a validation recording and score it")
    parser.add_argument("model", help="checkpoint written by 'trainer fit' (model.pt)")
    parser.add_argument("recording", help="validation recording (.csv or .npz)")
    parser.add_argument("--out-dir", default="evaluation", help="where the report and PNGs go (evaluation/)")
    parser.add_argument(
        "--smoothing",
        type=float,
        default=PAPER_RUN_SMOOTHING_S,
        help="trailing moving average in s applied before the Allan analysis (paper: 0.5)",
    )
    parser.add_argument(
        "--holdout",
        metavar="SPEC",
        help="score only the held-out part of the recording (as 'trainer compare --holdout'): F or last:F, "
        "first:F, T0: or :T1",
    )
    parser.add_argument(
        "--inject",
        choices=INPUT_PRESETS,
        help="add this known input to the recording and report how much of it the model keeps",
    )
    add_channels_option(
        parser, "score MODEL/<channel>.pt (MODEL: a 'trainer fit --channels' directory) into OUT/<channel>"
    )
    parser.set_defaults(func=run)


def _mg(value: float) -> str:
    """A figure in mg; n/a where the scored part has no sample (a branch it never ramps on)."""
    return f"{value:.4g} mg" if math.isfinite(value) else "n/a"


def drift_lines(result: Any) -> list[str]:
    """The headline (drift left, always), ground-truth details and warnings, one line each."""
    from trainer.scoring.verdict import Figures, worse_than_uncompensated

    lines = []
    for name, score in result.drift.items():
        reference = "" if score.t_ref_c is None else f" relative to T_ref {score.t_ref_c:.2f} degC"
        lines.append(
            f"residual drift vs true_drift_mg{reference} [{name}]: RMS {score.residual_rms_mg:.4g} mg, "
            f"max |.| {score.residual_max_abs_mg:.4g} mg (uncompensated drift RMS "
            f"{score.raw_drift_rms_mg:.4g} mg)"
        )
    for name in [n for n in result.static if n != "raw"]:
        left, raw = result.static[name], result.static["raw"]
        lines.append(
            f"drift left, deviation from a constant [{name}]: RMS {_mg(left.rms_mg)} (uncompensated "
            f"{_mg(raw.rms_mg)}), max |.| {_mg(left.max_abs_mg)}, heating RMS {_mg(left.heating_rms_mg)}, "
            f"cooling RMS {_mg(left.cooling_rms_mg)}; noise floor {_mg(result.noise_floor_mg)}"
            + ("" if result.drift else " (no true_drift_mg: scored as a static recording)")
        )
    for name in [n for n in result.static_in_range if n != "raw"]:
        left, raw = result.static_in_range[name], result.static_in_range["raw"]
        lines.append(
            f"drift left inside the trained range [{name}]: RMS {_mg(left.rms_mg)} (uncompensated {_mg(raw.rms_mg)})"
        )
    for name in [n for n in result.static if n != "raw"]:
        # the sign-off's guard (trainer report, codegen export of a --holdout fit): said where it is measured too
        model_in, raw_in = (
            math.nan if x is None else x.rms_mg
            for x in (result.static_in_range.get(name), result.static_in_range.get("raw"))
        )
        figures = Figures(
            "scored part",
            result.static[name].rms_mg,
            result.static["raw"].rms_mg,
            model_in,
            raw_in,
            result.noise_floor_mg,
        )
        guard = worse_than_uncompensated(name, figures)
        if not guard.ok:
            lines.append(f"warning [{name}]: it leaves more drift than no compensation here: {guard.detail}")
    for name, fraction in result.out_of_range_fraction.items():
        if fraction > 0:
            share = f"{100 * fraction:.2f} %" if fraction >= 5e-5 else f"{100 * fraction:.1g} %"
            lines.append(
                f"warning [{name}]: {share} of samples lie outside the model's valid temperature range"
            )
    return lines


def run(args: argparse.Namespace) -> int:
    if args.channels is not None:
        return run_per_channel(args, run, recordings=("recording",), out_dirs=("out_dir",), model="model")
    from trainer.checkpoint import load_model
    from trainer.data.channels import model_view, relabel_units, signal_of
    from trainer.data.holdout import overlap_warning, parse_holdout, split
    from trainer.data.plausibility import check_scored
    from trainer.data.recording import data_fingerprint
    from trainer.data.recording_io import read_recording
    from trainer.scoring.allan import plot_allan
    from trainer.scoring.compare import compensate_after
    from trainer.scoring.evaluate import evaluate, truth_reference_c
    from trainer.scoring.inject import injected_input, input_kept
    from trainer.scoring.plots import plot_series
    from trainer.selection import shown_name
    from trainer.train_stats import TrainStats

    check_finite("--smoothing", args.smoothing, maximum=MAX_SECONDS)
    check_report_dir(Path(args.out_dir), "evaluate")  # an existing file or an unwritable place too
    model, checkpoint = load_model(args.model)
    stats = TrainStats.of_checkpoint(checkpoint)
    # the model's own channel (gyro0_x of a multi-channel file), never the file's accel_mg
    rec = whole = check_scored(model_view(read_recording(args.recording), stats.channel, args.model))
    lead_in = None
    scored = f"{Path(args.recording).name}, all {len(rec)} rows"
    if args.holdout is not None:
        holdout = parse_holdout(args.holdout)
        train_part, rec = split(rec, holdout)
        scored = (
            f"the part of {Path(args.recording).name} --holdout {args.holdout} holds out: {len(rec)} of "
            f"{len(whole)} rows, t = {rec.time_s[0]:.6g} .. {rec.time_s[-1]:.6g} s"
        )
        # a held-out end part is scored with the state run through the part before it (firmware that
        # has run since power-on); a held-out start part starts cold, as at power-on
        lead_in = train_part.without_truth() if holdout.side == "last" else None
    name = shown_name(str(checkpoint["method"]), stats)
    compensated = compensate_after(model, rec.without_truth(), lead_in)
    lo, hi = checkpoint["valid_temp_range_c"]
    outside = (rec.temp_c < lo) | (rec.temp_c > hi)
    reference = truth_reference_c(model)
    references = {} if reference is None else {name: reference}
    result = evaluate(
        rec,
        {name: compensated},
        out_of_range={name: outside},
        smoothing_s=args.smoothing,
        references=references,
    )

    signal = signal_of(rec, stats.channel)
    out_dir = Path(args.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    text = f"{signal.heading}\n{result.table.to_text()}"
    extra = [f"scored: {scored}", *drift_lines(result)]
    if args.inject is not None:
        kept = input_kept(model, rec, injected_input(rec, args.inject))
        extra.append(
            f"input kept [{name}]: {100 * kept.gain:.1f} % of the injected '{args.inject}' input "
            f"(RMS {kept.input_rms_mg:.4g} mg; removed or distorted RMS {kept.error_rms_mg:.4g} mg)"
        )
    # a held-out part the model was trained on is not held out: said in the output and the report
    warning = overlap_warning(
        stats,
        rec,
        data_fingerprint(rec),
        whole=whole,
        what="validation" if args.holdout is None else "held-out",
    )
    if warning:
        extra.append(warning)
    print(relabel_units(text, signal.unit))
    for line in extra:
        print(relabel_units(line, signal.unit))
    report = [
        f"# Evaluation of {Path(args.model).name} on {Path(args.recording).name}: channel {signal.heading}",
        "",
        f"Validation smoothing: {result.smoothing_s} s trailing moving average before the Allan analysis.",
        "",
        f"Table 1 of channel {signal.heading}:",
        "",
        result.table.to_markdown(),
        "",
        *[f"- {line}" for line in extra],
        "",
    ]
    outputs = [out_dir / name for name in ("report.md", "fig12_compensated.png", "fig13_allan.png")]
    with atomic_outputs(outputs) as (report_tmp, fig12_tmp, fig13_tmp):  # all three or none
        report_tmp.write_text(relabel_units("\n".join(report), signal.unit))
        plot_series(
            rec.time_s,
            result.smoothed,
            fig12_tmp,
            title=f"Compensation on validation data ({result.smoothing_s} s smoothing)",
            signal=signal,
        )
        plot_allan(result.curves, fig13_tmp, title="Allan deviation after compensation", signal=signal)
    record_outputs(out_dir, "evaluate", [p.name for p in outputs])
    print(f"report and figures written to {out_dir}/")
    return 0
