"""``--channels all|LIST``: the one declaration every per-channel command uses.

``trainer import``, ``fit``, ``evaluate``, ``compare``, ``diagnose`` and ``codegen export`` add
it with :func:`add_channels_option`; the names are checked against a recording by
:func:`trainer.data.channels.select_channels`. Per-channel outputs go to ``<OUT>/<channel>``
(:func:`channel_output`).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

from trainer.data.channels import Channel, parse_channels_option, sort_key
from trainer.data.recording import Recording
from trainer.data.recording_io import MODEL_SUFFIX  # trainer fit --channels writes OUT/<channel>.pt
from trainer.errors import UserError

CHANNELS_OPTION = "--channels"
INDEX_FILE = "channels.json"  # ... and OUT/channels.json (what was fitted, units)


def _channels(text: str) -> tuple[str, ...]:
    try:
        return parse_channels_option(text)
    except UserError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--channels ")) from None


def add_channels_option(parser: argparse.ArgumentParser, what: str) -> None:
    """Add ``--channels``; ``what`` says what the command does per channel (for the help text)."""
    parser.add_argument(
        CHANNELS_OPTION,
        type=_channels,
        metavar="all|LIST",
        help=f"multi-channel recordings: {what} for each channel, 'all' or a list such as "
        "accel0_z,gyro0_x (column names: shared/specs/recording-format.md, 'Several channels')",
    )


def channel_output(out: str | Path, channel: str, suffix: str = "") -> Path:
    """Where a per-channel output of a command whose output is ``out`` goes: ``out/<channel><suffix>``."""
    return Path(out) / f"{channel}{suffix}"


def model_files(directory: str | Path, wanted: tuple[str, ...]) -> list[Path]:
    """The per-channel models ``trainer fit --channels`` wrote into ``directory``, as ``wanted``: the
    channels its index (:data:`INDEX_FILE`) lists, each of whose files must be there (a file lost in a
    copy would otherwise drop its channel from an export without a word)."""
    root = Path(directory)
    if not root.is_dir():
        raise UserError(
            f"{root}: {CHANNELS_OPTION} reads a directory written by 'trainer fit {CHANNELS_OPTION}'"
        )
    listed = _indexed_models(root)
    available = sorted(listed, key=sort_key)
    names = available if wanted == ("all",) else list(wanted)
    missing = [name for name in names if name not in available]
    if missing:
        raise UserError(
            f"{root}: {CHANNELS_OPTION} {missing[0]!r} has no model in this directory; available: "
            f"{', '.join(available)}"
        )
    lost = [name for name in names if not (root / listed[name]).is_file()]
    if lost:
        raise UserError(
            f"{root}: {INDEX_FILE} lists {', '.join(lost)}, but {listed[lost[0]]} is not there (lost in a copy?): "
            f"copy it back or fit again"
        )
    return [root / listed[name] for name in names]


def _indexed_models(root: Path) -> dict[str, str]:
    """``{channel: model file name}`` of the index ``trainer fit --channels`` wrote into ``root``."""
    index = root / INDEX_FILE
    if not index.is_file():
        raise UserError(
            f"{root}: no {INDEX_FILE}, so not a directory written by 'trainer fit {CHANNELS_OPTION}': "
            f"give the model files themselves, without {CHANNELS_OPTION}"
        )
    try:
        entries = json.loads(index.read_text(encoding="utf-8"))["channels"]
        listed = {str(e["channel"]): str(e["model"]) for e in entries}
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) else f"{type(exc).__name__}: {exc}"
        raise UserError(f"{index}: not the index 'trainer fit {CHANNELS_OPTION}' writes ({why})") from None
    if not listed:
        raise UserError(f"{index}: lists no channel")
    if bad := [m for m in listed.values() if Path(m).name != m or not m.endswith(MODEL_SUFFIX)]:
        raise UserError(f"{index}: model {bad[0]!r} is not a {MODEL_SUFFIX} file of this directory")
    return listed


def channel_prefix(name: str, number: int, count: int) -> str:
    """What a progress line on stderr starts with when a command runs channel by channel."""
    return f"[{name}, channel {number} of {count}] "


PREFIX_ATTR = "progress_prefix"  # the per-channel run sets it on the command's arguments


def run_per_channel(
    args: argparse.Namespace,
    run_one: Callable[[argparse.Namespace], int],
    *,
    recordings: tuple[str, ...],
    out_dirs: tuple[str, ...] = (),
    out_files: tuple[str, ...] = (),
    model: str | None = None,
    refuse: Callable[[Channel], str | None] | None = None,
) -> int:
    """Run a one-channel command once per ``--channels`` channel.

    Each channel's one-channel view of every recording argument (``recordings``: attribute
    names) is written to a temporary ``.npz`` named ``<stem>[<channel>].npz``; the command's
    output directories (``out_dirs``) become ``<dir>/<channel>``, output files (``out_files``)
    ``<stem>.<channel><suffix>``, and ``model`` (a ``trainer fit --channels`` directory)
    ``<dir>/<channel>.pt``. Text the command prints or writes (.md, .txt, .json) says the
    channel's unit instead of mg (:func:`trainer.data.channels.relabel_units`).
    """
    from trainer.data.channels import one_axis_left_out, select_channels
    from trainer.data.recording_io import read_recording

    given = {attr: getattr(args, attr) for attr in recordings if getattr(args, attr) is not None}
    recs = {attr: read_recording(path) for attr, path in given.items()}
    first = next(iter(recs.values()))
    channels = select_channels(first, args.channels)
    if (note := one_axis_left_out(first, args.channels, channels)) is not None:
        print(note, file=sys.stderr, flush=True)
    for channel in channels:
        reason = refuse(channel) if refuse is not None else None
        if reason is not None:
            raise UserError(reason)
    models = model_files(getattr(args, model), tuple(c.name for c in channels)) if model else []
    made: list[Path] = []  # outputs this run created, removed if any channel fails
    try:
        return _each_channel(args, run_one, channels, recs, given, out_dirs, out_files, model, models, made)
    except BaseException:
        for path in reversed(made):  # nothing half-made is left behind: not even the channels done
            if path.is_dir():
                shutil.rmtree(path)
            else:
                path.unlink(missing_ok=True)
        raise


def _each_channel(
    args: argparse.Namespace,
    run_one: Callable[[argparse.Namespace], int],
    channels: list[Channel],
    recs: dict[str, Recording],
    given: dict[str, str],
    out_dirs: tuple[str, ...],
    out_files: tuple[str, ...],
    model: str | None,
    models: list[Path],
    made: list[Path],
) -> int:
    """The channels in turn; every output path created is appended to ``made`` before it is written.
    An error of one channel names the user's file and the channel, not the temporary view."""
    from trainer.atomic_dir import check_output_directory
    from trainer.data.channels import channel_view, relabel_units, select_channels
    from trainer.data.recording_io import write_recording
    from trainer.errors import check_output_path

    def note(path: Path) -> None:
        if not path.exists():
            made.append(path)

    status = 0
    with tempfile.TemporaryDirectory(prefix="channels-") as tmp:
        for index, channel in enumerate(channels):
            sub = argparse.Namespace(**vars(args))
            sub.channels = None
            setattr(sub, PREFIX_ATTR, channel_prefix(channel.name, index + 1, len(channels)))
            views: dict[str, str] = {}
            for attr, rec in recs.items():
                select_channels(rec, (channel.name,))  # every recording must carry the channel
                path = Path(tmp) / f"{Path(given[attr]).stem}[{channel.name}].npz"
                write_recording(channel_view(rec, channel), path)
                setattr(sub, attr, str(path))
                views[str(path)] = f"{given[attr]} (channel {channel.name})"
            for attr in out_dirs:
                if getattr(args, attr) is not None:
                    directory = Path(getattr(args, attr))
                    check_output_directory(directory)  # a file there is one line, not a traceback
                    note(directory)
                    directory.mkdir(exist_ok=True)
                    note(channel_output(directory, channel.name))
                    setattr(sub, attr, str(channel_output(directory, channel.name)))
            for attr in out_files:
                if getattr(args, attr) is not None:
                    original = Path(getattr(args, attr))
                    per_channel = original.with_name(f"{original.stem}.{channel.name}{original.suffix}")
                    check_output_path(per_channel, inputs=list(given.values()))  # never over an input
                    note(per_channel)
                    setattr(sub, attr, str(per_channel))
            if model:
                setattr(sub, model, str(models[index]))
            print(f"== {channel.name} [{channel.label}]", flush=True)
            captured = io.StringIO()
            try:
                with contextlib.redirect_stdout(captured):
                    status = max(status, run_one(sub))
            except UserError as exc:
                raise UserError(_as_the_user_named(str(exc), views)) from None
            print(
                _as_the_user_named(relabel_units(captured.getvalue(), channel.unit), views),
                end="",
                flush=True,
            )
            _relabel_outputs(sub, out_dirs, out_files, channel.unit, views)
    return status


def _as_the_user_named(text: str, views: dict[str, str]) -> str:
    """``text`` with each temporary one-channel view's path replaced by the user's file and channel
    (a report that named ``/tmp/channels-x/imu[gyro0_z].npz`` named a file deleted after the run)."""
    for view, named in views.items():
        text = text.replace(view, named)
        text = text.replace(Path(view).name, named)  # a title that names the file alone
    return text


def _relabel_outputs(
    sub: argparse.Namespace,
    out_dirs: tuple[str, ...],
    out_files: tuple[str, ...],
    unit: str,
    views: dict[str, str],
) -> None:
    """The text outputs (.md, .txt, .json) say the channel's unit and the user's file."""
    from trainer.data.channels import relabel_units

    paths: list[Path] = []
    for attr in out_dirs:
        if getattr(sub, attr) is not None and Path(getattr(sub, attr)).is_dir():
            paths += [p for p in Path(getattr(sub, attr)).rglob("*") if p.suffix in (".md", ".txt", ".json")]
    paths += [Path(getattr(sub, attr)) for attr in out_files if getattr(sub, attr) is not None]
    for path in paths:
        if path.is_file():
            text = path.read_text(encoding="utf-8")
            relabelled = _as_the_user_named(relabel_units(text, unit) if unit != "mg" else text, views)
            if relabelled != text:
                path.write_text(relabelled, encoding="utf-8")
