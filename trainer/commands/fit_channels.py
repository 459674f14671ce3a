"""``trainer fit --channels``: one model per channel of a multi-channel recording, into a directory.

Layout (docs/channels.md): ``OUT/<channel>.pt`` is an ordinary checkpoint of the channel's
one-channel view (its ``train_stats`` name the channel and unit), so ``evaluate``, ``codegen
export`` and the flight-stack parameter files read it like any model; ``OUT/channels.json`` lists
the channels with their units and fit figures. All models are fitted before anything is written,
and the set is swapped in as one (trainer/atomic_dir.py): an interrupted run leaves the old set.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from trainer import methods
from trainer.atomic_dir import atomic_directory, check_output_directory
from trainer.data.channels import (
    channel_view,
    method_refusal,
    one_axis_left_out,
    select_channels,
    shared_temperature_note,
)
from trainer.errors import UserError
from trainer.options.channels import INDEX_FILE, MODEL_SUFFIX, channel_prefix
from trainer.reference import OffsetPolicy


def fit_channels(args: argparse.Namespace, options: dict[str, Any], policy: OffsetPolicy) -> int:
    from trainer.checkpoint import save_model
    from trainer.commands.selection_output import (
        checked_method,
        print_fitted,
        print_held_out,
        print_selection,
        progress_log,
    )
    from trainer.data.holdout import part_left_for_training
    from trainer.data.plausibility import check_training
    from trainer.data.recording_io import read_recording
    from trainer.options.workers import jobs_task_map
    from trainer.scoring.fit_holdout import with_held_out_score
    from trainer.selection import fit_with_selection

    method = checked_method(args.method)
    if Path(args.output).suffix.lower() == MODEL_SUFFIX and not Path(args.output).is_dir():
        raise UserError(
            f"{args.output}: --channels writes a directory of models (OUT/<channel>{MODEL_SUFFIX}), and this "
            f"names a model file: give a directory, or leave out --channels to fit the one-channel column"
        )
    check_output_directory(args.output)  # before a possibly long fit
    whole = read_recording(args.train)
    train = part_left_for_training(whole, args.holdout)
    channels = select_channels(train, args.channels)
    for note in (one_axis_left_out(train, args.channels, channels), shared_temperature_note(train, channels)):
        if note is not None:
            print(note, file=sys.stderr, flush=True)
    checked = []
    for channel in channels:  # refuse before the first (possibly long) fit
        refusal = method_refusal(method.name, method.family, channel)
        if refusal is not None:
            raise UserError(f"{train.source}: {refusal}")
        view = channel_view(train, channel)
        checks = check_training(view, method, accept=args.accept_implausible, temp_column=channel.temp_column)
        checked.append((channel, view, checks))
    fitted = []
    with jobs_task_map(args.jobs) as tasks:  # one cluster for every channel, if any
        for number, (channel, view, checks) in enumerate(checked, start=1):
            log = progress_log(args, prefix=channel_prefix(channel.name, number, len(checked)))
            model, stats = fit_with_selection(args.method, view, options, policy, log=log, tasks=tasks)
            stats = with_held_out_score(model, stats, channel_view(whole, channel), args.holdout)
            fitted.append((channel, model, stats, checks))
    index: dict[str, Any] = {"method": args.method, "train": str(args.train), "channels": []}
    # old set or new set, never a mix: the models an earlier fit listed that this one does not fit go
    with atomic_directory(args.output, drop=previous_models(Path(args.output))) as staging:
        for channel, model, stats, _ in fitted:
            save_model(
                model,
                staging / f"{channel.name}{MODEL_SUFFIX}",
                train_stats=stats,
                valid_temp_range_c=stats.temp_range_c,
            )
            index["channels"].append(
                {
                    "channel": channel.name,
                    "model": f"{channel.name}{MODEL_SUFFIX}",
                    "unit": channel.label,
                    "column": channel.column,
                    "temp_column": channel.temp_column,
                    "temp_range_c": list(stats.temp_range_c),
                    "fit_residual_rms": stats.fit_residual_rms_mg,
                    "method": methods.name_of(model),
                    **({"auto_chose": stats.selection["chosen"]} if stats.selection is not None else {}),
                }
            )
        (staging / INDEX_FILE).write_text(json.dumps(index, indent=2) + "\n", encoding="utf-8")
    for channel, model, stats, checks in fitted:
        checks.print_warnings()
        if stats.selection is not None:
            print(f"== {channel.name} [{channel.label}]")
            print_selection(stats)
        destination = f"{args.output}/{channel.name}{MODEL_SUFFIX}"
        print_fitted(model, stats, destination, channel.unit, channel.name)
        print_held_out(stats, destination, channel.unit)
    return 0


def previous_models(out: Path) -> list[str]:
    """The model files the index of an earlier ``fit --channels`` into ``out`` lists (none when it has
    none, or one that cannot be read: then nothing is dropped)."""
    try:
        entries = json.loads((out / INDEX_FILE).read_text(encoding="utf-8"))["channels"]
        return [str(e["model"]) for e in entries if Path(str(e["model"])).name == str(e["model"])]
    except (OSError, ValueError, KeyError, TypeError):
        return []
