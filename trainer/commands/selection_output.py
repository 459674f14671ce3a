"""What ``trainer fit`` prints and checks around ``--method auto`` (shared by one channel and many)."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from trainer import methods
from trainer.data.channels import relabel_units
from trainer.reference import recursive_note
from trainer.selection import AUTO, record_lines, resolved, shown_name
from trainer.train_stats import TrainStats

if TYPE_CHECKING:
    from trainer.compensator import Compensator


def checked_method(name: str) -> methods.Method:
    """The method whose training checks apply (auto: the cubic's temperature span, its simplest fit; a
    variant such as ``physics-branches``: its registered method's)."""
    return methods.get(methods.CUBIC if name == AUTO else resolved(name, None)[0])


def progress_log(args: argparse.Namespace, prefix: str = "") -> Any:
    """Progress lines on stderr (a cross-validation fits every candidate once per segment);
    ``prefix`` says which channel of how many (a six-channel ``auto`` runs for minutes)."""
    if getattr(args, "quiet", False):
        return None
    return lambda message: print(f"{prefix}{message}", file=sys.stderr, flush=True)


def print_selection(stats: TrainStats) -> None:
    """The table that chose an auto model (from the checkpoint's record), and the choice in one line."""
    record = stats.selection
    if record is not None:
        for line in record_lines(record):
            print(line)


def print_fitted(
    model: Compensator, stats: TrainStats, destination: str, unit: str, channel: str = ""
) -> None:
    """What a fitted model is, in the channel's unit: training rows and range, fit residual, the
    method's own summary (the physics structure, its parameters and warnings) and the offset policy.
    One channel and each channel of many print the same (``channel``: its name after the method's)."""
    name = shown_name(methods.name_of(model), stats) + (f" {channel}" if channel else "")
    lines = [
        f"{name}: fitted on {stats.n_samples} samples ({stats.temp_range_c[0]:.2f} .. {stats.temp_range_c[1]:.2f} "
        f"degC), fit residual RMS {stats.fit_residual_rms_mg:.4g} mg -> {destination}",
        *model.describe(),
        f"{name}: {model.offset.describe() if model.offset else recursive_note(unit)}",
    ]
    for line in lines:
        print(relabel_units(line, unit))


def print_held_out(stats: TrainStats, destination: str, unit: str) -> None:
    """``trainer fit --holdout``: the model's figures on the part it held out, the sign-off guard's line."""
    from trainer.data.channels import UNIT_LABELS
    from trainer.scoring.fit_holdout import held_out_line

    line = held_out_line(stats, destination, UNIT_LABELS[unit])
    if line is not None:
        print(line)
