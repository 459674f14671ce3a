"""``trainer diagnose RECORDING``: name the physics a simulation leaves out of a recording."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

from trainer.options.channels import add_channels_option, run_per_channel

if TYPE_CHECKING:
    from trainer.diagnose.result import Diagnosis


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and 0.0 <= value < 0.5):
        raise argparse.ArgumentTypeError(f"{text!r} is not a fraction in [0, 0.5)")
    return value


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``trainer diagnose``."""
    parser = subparsers.add_parser(
        "diagnose",
        help="find the physics a simulation leaves out of a recording (mismatch finder)",
        description=(
            "Calibrate a simulation (--sim, default: bias_poly plus noise) to a recording, locate where the "
            "residual is structured, name the catalogue effects that were left out and show the improvement. "
            "See docs/diagnose.md."
        ),
    )
    parser.add_argument("recording", help="recording, .csv or .npz (true_* columns are ignored)")
    parser.add_argument("--sim", metavar="CONFIG.toml", help="the simulation you believe in (physics TOML)")
    parser.add_argument("--json", metavar="OUT.json", help="write the machine-readable result")
    parser.add_argument(
        "--report", metavar="DIR", help="write a report directory (Markdown, plots, augmented TOML)"
    )
    parser.add_argument(
        "--holdout",
        type=_fraction,
        default=0.25,
        metavar="F",
        help="score both models on the last fraction F of the run after fitting on the rest (default 0.25; 0: off)",
    )
    add_channels_option(
        parser, "diagnose the channel (parameters in its unit: amp_dps on a gyroscope, amp_pa on a barometer)"
    )
    parser.set_defaults(func=run)


def _check_outputs(args: argparse.Namespace) -> None:
    """Refuse bad output paths before a long analysis."""
    from pathlib import Path

    from trainer.atomic_dir import check_output_directory
    from trainer.data.recording_io import RECORDING_SUFFIXES
    from trainer.diagnose.report import check_report_target
    from trainer.errors import UserError, check_output_path

    inputs = [p for p in (args.recording, args.sim) if p]
    if args.json:
        parent = Path(args.json).parent
        if not parent.is_dir():
            raise UserError(f"{args.json}: output directory {parent} does not exist")
        check_output_path(args.json, inputs=inputs)  # the JSON once overwrote the recording it read
        if Path(args.json).suffix.lower() in RECORDING_SUFFIXES:
            raise UserError(
                f"{args.json}: a recording's name ({Path(args.json).suffix}) for the JSON document "
                "(arguments swapped? the recording comes first, --json names the document)"
            )
    if args.report:
        check_output_directory(args.report)  # an existing file (an input, say) is refused there
        check_report_target(args.report)  # a directory of the user's files too


def run(args: argparse.Namespace) -> int:
    if args.channels is not None:
        return run_per_channel(
            args, run, recordings=("recording",), out_dirs=("report",), out_files=("json",)
        )
    from trainer.data.plausibility import check_scored
    from trainer.data.recording_io import read_recording
    from trainer.diagnose import diagnose
    from trainer.diagnose.report import write_json, write_report
    from trainer.physics.config import load_config

    _check_outputs(args)
    sim = load_config(args.sim) if args.sim else None
    rec = check_scored(read_recording(args.recording))
    result = diagnose(rec, sim, holdout_fraction=args.holdout, progress=True)
    if args.json:
        write_json(result, args.json)
    if args.report:
        write_report(result, args.report)
    print(summary(result))
    if args.json:
        print(f"JSON written to {args.json}")  # --channels: one per channel, <stem>.<channel>.json
    if args.report:
        print(f"report written to {args.report}/")
    return 0


def every_output(result: Diagnosis) -> str:
    """The terminal summary, the report's Markdown and the JSON of one diagnosis, built in memory:
    the benches build them for every case, so that a finding one of them cannot take fails there,
    not for the user (a named noise trend once broke the next steps of the terminal and the report,
    unseen by benches that read only the findings)."""
    from trainer.diagnose.document import json_text
    from trainer.diagnose.report import markdown

    return "\n".join((summary(result), markdown(result), json_text(result)))


def summary(result: Diagnosis) -> str:
    """A few lines for the terminal."""
    from trainer.diagnose.next_steps import next_steps, terminal_lines
    from trainer.diagnose.report import limit_sizes, value_text
    from trainer.diagnose.select import MAX_ADDED, THRESHOLD
    from trainer.diagnose.shared import shared_text
    from trainer.diagnose.verdict import ambiguity_line
    from trainer.physics.catalogue.units import channel_param_name

    before, after = result.before, result.after
    lines = [f"baseline: {', '.join(result.baseline.identifiers)}"]
    # the --sim's effects as calibrated (JSON baseline_calibrated) outside the plausible range, and not needed
    for effect, flags in result.implausible_baseline():
        params = ", ".join(f"{k}={value_text(v)}" for k, v in result.params(effect.params).items())
        lines.append(
            f"simulation: {effect.identifier} calibrated implausibly [{params}]{result.label} ({'; '.join(flags)})"
        )
    lines += [
        f"simulation: {n.effect} not supported{result.label} ({n.reason})" for n in result.not_supported
    ]
    if result.left_out:
        for e in result.left_out:
            params = ", ".join(f"{k}={value_text(v)}" for k, v in result.params(e.params).items())
            extra = result.label + (
                f" (ambiguous with {', '.join(e.ambiguous_with)})" if e.ambiguous_with else ""
            )
            extra += f" (would absorb a {' or '.join(e.absorbs)} on this profile)" if e.absorbs else ""
            extra += f" (implausible: {'; '.join(e.flags)})" if e.flags else ""
            lines.append(f"left out: {e.effect} [{params}] BIC -{e.evidence.delta_bic_when_added:.1f}{extra}")
    else:
        lines.append("left out: nothing found beyond the simulation")
    lines += [ambiguity_line(a, result.label, result.unit) for a in result.ambiguous]
    for n in result.not_identifiable:
        lines.append(f"not identifiable: {n.effect}{result.label} ({n.recommended_test or n.reason})")
    # the first line above that names an effect: "absorbed: ..." or "ambiguous ...: ..."
    listed: dict[str, str] = {}
    for a in result.ambiguous:
        for x in a.effects:
            listed.setdefault(
                x, "absorbed" if a.absorbed else "undetermined" if a.undetermined else "ambiguous"
            )
    for t in result.tested:
        if t.note.startswith("weakly identifiable"):
            # one of an ambiguity above: the weakness is why it is ambiguous, not a second finding
            which = f"{t.effect}{result.label}" + (
                f", in the {listed[t.effect]} line above" if t.effect in listed else ""
            )
            lines.append(f"{t.note.replace('weakly identifiable', f'weakly identifiable: {which}', 1)}")
    for u in result.undetected:
        amp = channel_param_name(u.amp_name, result.unit)
        lines.append(f"not named: {u.effect}{result.label}: this run names it from {amp} = {limit_sizes(u)}")
    for m in result.suggestive:
        params = ", ".join(f"{k}={value_text(v)}" for k, v in result.params(m.params).items())
        lines.append(
            f"near miss (not named): {m.effect} [{params}] BIC -{m.delta_bic:.1f}{result.label}"
            + (f" (one of {m.joint} placed jointly; the BIC is theirs together)" if m.joint > 1 else "")
            + ", "
            + (
                f"below the criterion's {THRESHOLD:g}"
                if m.delta_bic < THRESHOLD
                else f"the search stopped at its {MAX_ADDED} effects"
            )
            + (f"; {shared}" if (shared := shared_text(m.shares)) else "")
        )
    lines.append(
        f"fit: block RMS {before.rms_block_mg:.4g} -> {after.rms_block_mg:.4g} {result.signal.label}, "
        f"BIC {before.bic:.1f} -> {after.bic:.1f}"
    )
    if result.holdout:
        hb, ha = result.holdout.before, result.holdout.after
        # One figure: the least-squares refit extrapolated bare (see holdout.HEADLINE).
        lines.append(
            f"held-out tail: block RMS {hb.test_rms_block_mg_ols:.4g} -> {ha.test_rms_block_mg_ols:.4g} "
            f"{result.signal.label}"
            " (refitted on the rest, extrapolated as a compensator would)"
            + (f"; {result.holdout.note}" if result.holdout.note else "")
        )
    lines += terminal_lines(next_steps(result))
    lines.append(f"({result.seconds:.1f} s)")
    return "\n".join(lines)
