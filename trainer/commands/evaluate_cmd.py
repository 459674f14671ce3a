"""``trainer evaluate model.pt VALID.csv``: compensate a recording and print the paper's Table 1."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.errors import UserError, atomic_output

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
    parser.set_defaults(func=run)


def drift_lines(result: Any) -> list[str]:
    lines = []
    for name, score in result.drift.items():
        lines.append(
            f"residual drift vs true_drift_mg [{name}]: RMS {score.residual_rms_mg:.4g} mg, "
            f"max |.| {score.residual_max_abs_mg:.4g} mg (uncompensated drift RMS "
            f"{score.raw_drift_rms_mg:.4g} mg)"
        )
    for name, fraction in result.out_of_range_fraction.items():
        if fraction > 0:
            lines.append(
                f"warning [{name}]: {100 * fraction:.2f} % of samples lie outside the model's valid "
                f"temperature range"
            )
    return lines


def run(args: argparse.Namespace) -> int:
    from trainer.checkpoint import load_model
    from trainer.data.recording_io import read_recording
    from trainer.scoring.allan import plot_allan
    from trainer.scoring.evaluate import evaluate
    from trainer.scoring.plots import plot_series

    if args.smoothing < 0:
        raise UserError(f"--smoothing must be >= 0 s, got {args.smoothing}")
    model, checkpoint = load_model(args.model)
    rec = read_recording(args.recording)
    name = checkpoint["method"]
    compensated = model.compensate(rec.without_truth())
    lo, hi = checkpoint["valid_temp_range_c"]
    outside = (rec.temp_c < lo) | (rec.temp_c > hi)
    result = evaluate(rec, {name: compensated}, out_of_range={name: outside}, smoothing_s=args.smoothing)

    out_dir = Path(args.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    text = result.table.to_text()
    extra = drift_lines(result)
    print(text)
    for line in extra:
        print(line)
    report = [
        f"# Evaluation of {Path(args.model).name} on {Path(args.recording).name}",
        "",
        f"Validation smoothing: {result.smoothing_s} s trailing moving average before the Allan analysis.",
        "",
        result.table.to_markdown(),
        "",
        *[f"- {line}" for line in extra],
        "",
    ]
    with atomic_output(out_dir / "report.md") as tmp:
        tmp.write_text("\n".join(report))
    plot_series(
        rec.time_s,
        result.smoothed,
        out_dir / "fig12_compensated.png",
        title=f"Compensation on validation data ({result.smoothing_s} s smoothing)",
    )
    plot_allan(result.curves, out_dir / "fig13_allan.png", title="Allan deviation after compensation")
    print(f"report and figures written to {out_dir}/")
    return 0
