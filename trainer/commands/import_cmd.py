"""``trainer import FOREIGN -o OUT.csv|.npz``: convert a foreign logger's file or a flight log into a recording.

A PX4 ULog or ArduPilot DataFlash log (recognised by its magic bytes) takes ``--channel`` and
``--channels``; each of its time bases (sensor instances) becomes its own recording, written to
``OUT`` or, when there are several, to ``OUT_<instance>.ext``. Any other file is delimited text
mapped by the column options.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from trainer.data.flightlog import A_KIND, KIND_NAMES, KIND_SUFFIXES, log_kind
from trainer.data.flightlog_import import LogImport, import_flight_log, log_output
from trainer.data.flightlog_io import read_flight_log
from trainer.data.importer import import_foreign
from trainer.data.plausibility import Plausibility
from trainer.data.recording import ONE_AXIS_COLUMNS, Recording
from trainer.data.recording_io import MODEL_SUFFIX, RECORDING_SUFFIXES, recording_format, write_recording
from trainer.errors import SWAPPED_HINT, UserError, check_output_path
from trainer.options.importing import add_import_arguments, import_options, log_import_options


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``trainer import`` (its options: :mod:`trainer.options.importing`)."""
    parser = subparsers.add_parser(
        "import",
        help="convert a foreign logger's delimited file or a PX4/ArduPilot flight log into a recording",
        description=(
            "Convert a tab/comma/semicolon-delimited file, a PX4 ULog (.ulg) or an ArduPilot DataFlash log "
            "(.bin) into a recording (.csv or .npz). Time starts at 0; a time axis whose jitter breaks the "
            "1 percent rule is an error unless --resample or --retime is given."
        ),
    )
    add_import_arguments(parser)
    parser.set_defaults(func=run)


UNSUPPORTED_LOGS = {".tlog": "a MAVLink telemetry log (.tlog)"}  # said by name, not as a delimited file


def run(args: argparse.Namespace) -> int:
    kind = log_kind(args.foreign)
    what = UNSUPPORTED_LOGS.get(Path(args.foreign).suffix.lower())
    named = KIND_SUFFIXES.get(Path(args.foreign).suffix.lower())  # a log's name on a file that is not one
    if kind is None and named is not None and Path(args.foreign).is_file():
        raise UserError(
            f"{args.foreign}: named as {A_KIND[named]} log, but its first bytes are not that log's header "
            "(a damaged, truncated or renamed file?)"
        )
    if kind is None and what is not None:
        raise UserError(
            f"{args.foreign}: {what} is not read by this tool; import the flight's PX4 ULog (.ulg) or ArduPilot "
            "DataFlash log (.bin), which log each IMU at its own rate with its temperature"
        )
    if kind is None:
        _refuse_own_files(args.foreign, columns_given=args.temp is not None or args.preset is not None)
    if args.list_channels:
        if kind is None:
            raise UserError(f"{args.foreign}: --list-channels applies to flight logs (ULog, DataFlash) only")
        log = read_flight_log(args.foreign)
        print(f"{args.foreign}: {KIND_NAMES[log.kind]} log, {len(log.channels)} channels")
        for channel in log.channels.values():
            print(f"  {channel.summary()}")
        for notice in log.notices:
            print(f"note: {notice}")
        return 0
    if args.output is None:
        raise UserError("trainer import: -o/--output OUT is required")
    recording_format(args.output)  # reject a bad extension before any work
    checks = Plausibility(accept=args.accept_implausible)
    if kind is not None:
        imported = _import_log(args, kind, checks)
        several = len(imported.recordings) > 1
        outputs = {log_output(args.output, name, several): rec for name, rec in imported.recordings.items()}
    else:
        imported = LogImport({})
        outputs = {Path(args.output): _import_text(args, checks)}
    _write_all(outputs, [args.foreign])
    for notice in imported.notices:
        print(f"note: {notice}")
    checks.print_warnings()
    for path, rec in outputs.items():
        how = next((word for word in ("resampled", "retimed") if f"{word}_from" in rec.meta), "as sampled")
        rate_hz = float(rec.meta["sample_rate_hz"])
        picked = f" ({rec.meta['channel']})" if kind is not None else ""
        if args.channels is not None:
            from trainer.data.channels import recording_channels

            picked = f" (channels {', '.join(recording_channels(rec))})"
        print(f"{path}: {len(rec)} rows at {rate_hz:.6g} Hz ({how}) from {args.foreign}{picked}")
    return 0


def _write_all(outputs: dict[Path, Recording], inputs: Sequence[str]) -> None:
    """Write every recording or none: a failure removes the ones already written."""
    for path in outputs:
        check_output_path(path, inputs=inputs)
    written: list[Path] = []
    try:
        for path, rec in outputs.items():
            write_recording(rec, path)
            written.append(path)
    except BaseException:
        for path in written:
            path.unlink(missing_ok=True)
        raise


def _import_log(args: argparse.Namespace, kind: str, checks: Plausibility) -> LogImport:
    return import_flight_log(args.foreign, log_import_options(args, kind), checks)


def _refuse_own_files(path: str, *, columns_given: bool) -> None:
    """A model, or a recording this tool already wrote given without column options, to import: said
    as what it is (it said "--temp COLUMN is required", the options being checked before the file).
    A recording with its columns mapped is imported again (to resample it, say)."""
    suffix = Path(path).suffix.lower()
    if suffix == MODEL_SUFFIX:
        raise UserError(
            f"{path}: a model file ({MODEL_SUFFIX}) where a logger's file or a flight log is expected ({SWAPPED_HINT})"
        )
    ours = suffix in RECORDING_SUFFIXES and (
        RECORDING_SUFFIXES[suffix] != "csv" or _starts_as_a_recording(path)
    )
    if not columns_given and ours:
        raise UserError(
            f"{path}: already a recording of this tool's format (time_s, {', '.join(ONE_AXIS_COLUMNS)} columns): "
            "every command reads it as it is, no import needed (to resample it, map its columns: --time time_s "
            "--temp temp_c --accel accel_mg --accel-unit mg)"
        )


def _starts_as_a_recording(path: str) -> bool:
    """Whether the text file's header is the recording format's (``time_s``, ``temp_c`` and
    ``accel_mg`` among its comma-separated columns, after its ``# key=value`` lines)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as handle:
            for line in handle:
                if not line.startswith("#"):
                    return {"time_s", *ONE_AXIS_COLUMNS} <= {field.strip() for field in line.split(",")}
    except OSError:
        pass  # the reader names what is wrong with it
    return False


def _import_text(args: argparse.Namespace, checks: Plausibility) -> Recording:
    if args.channel is not None:
        raise UserError(
            f"{args.foreign}: --channel applies to flight logs; map a delimited file's columns with --accel"
        )
    return import_foreign(args.foreign, import_options(args), checks)
