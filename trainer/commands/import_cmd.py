"""``trainer import FOREIGN -o OUT.csv|.npz``: convert a foreign logger's file into a recording."""

from __future__ import annotations

import argparse
import math

from trainer.data.importer import (
    ACCEL_UNIT_TO_MG,
    DELIMITER_NAMES,
    GRAVITY_MODES,
    PRESETS,
    TIME_UNIT_SECONDS,
    ImportOptions,
    import_foreign,
    options_with_preset,
)
from trainer.data.recording_io import recording_format, write_recording

_DELIMITER_ALIASES = {"tab": "\t", "\\t": "\t", "comma": ",", "semicolon": ";"}


def _delimiter(text: str) -> str:
    delimiter = _DELIMITER_ALIASES.get(text, text)
    if delimiter not in DELIMITER_NAMES:
        raise argparse.ArgumentTypeError(f"{text!r} is not one of tab, comma (,), semicolon (;)")
    return delimiter


def _positive_hz(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of Hz")
    return value


def _resample(text: str) -> float | str:
    return text if text in ("auto", "none") else _positive_hz(text)


def _axes(text: str) -> tuple[str, ...]:
    names = tuple(name.strip() for name in text.split(","))
    if len(names) != 3 or not all(names):
        raise argparse.ArgumentTypeError(f"{text!r} is not three column names X,Y,Z")
    return names


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``trainer import``; options left out fall back to the preset, then to defaults."""
    parser = subparsers.add_parser(
        "import",
        help="convert a foreign logger's delimited file into a recording",
        description=(
            "Convert a tab/comma/semicolon-delimited file into a recording (.csv or .npz). Time starts "
            "at 0; a time axis whose jitter breaks the 1 percent rule is an error unless --resample or "
            "--retime is given."
        ),
    )
    parser.add_argument("foreign", metavar="FOREIGN", help="the foreign delimited file (with a header line)")
    parser.add_argument("-o", "--output", required=True, metavar="OUT", help="output recording, .csv or .npz")
    parser.add_argument("--preset", choices=sorted(PRESETS), help="column mapping of a known logger")
    parser.add_argument("--delimiter", type=_delimiter, help="tab, comma or semicolon (default: sniffed)")
    parser.add_argument("--time", metavar="COL", help="time column")
    parser.add_argument("--time-unit", choices=list(TIME_UNIT_SECONDS), help="unit of --time (default s)")
    parser.add_argument("--rate", type=_positive_hz, metavar="HZ", help="sample rate for --time-unit index")
    parser.add_argument("--temp", metavar="COL", help="sensor temperature column, degC")
    parser.add_argument("--accel", metavar="COL", help="the axis to compensate (becomes accel_mg)")
    parser.add_argument("--accel-unit", choices=list(ACCEL_UNIT_TO_MG), help="unit of the axes (default mg)")
    parser.add_argument(
        "--extra-axes", type=_axes, metavar="X,Y,Z", help="columns for accel_x_mg, accel_y_mg, accel_z_mg"
    )
    parser.add_argument(
        "--remove-gravity", choices=GRAVITY_MODES, help="subtract +-1 g (nominal) or the mean from accel_mg"
    )
    parser.add_argument("--sensor", metavar="NAME", help="sensor name for the metadata")
    parser.add_argument(
        "--resample",
        type=_resample,
        metavar="HZ|auto|none",
        help="interpolate onto a uniform grid (auto: same row count and span; none: enforce the jitter rule)",
    )
    parser.add_argument(
        "--retime",
        action="store_true",
        help="keep every sample and space the timestamps evenly over the same span (jitter up to 5 percent)",
    )
    parser.set_defaults(func=run)


def import_options(args: argparse.Namespace) -> ImportOptions:
    """The parsed ``trainer import`` options as :class:`ImportOptions` (``trainer fleet`` reuses it)."""
    return options_with_preset(
        args.preset,
        time=args.time,
        time_unit=args.time_unit,
        rate_hz=args.rate,
        temp=args.temp,
        accel=args.accel,
        accel_unit=args.accel_unit,
        extra_axes=args.extra_axes,
        remove_gravity=args.remove_gravity,
        sensor=args.sensor,
        resample=args.resample,
        retime=args.retime or None,
        delimiter=args.delimiter,
    )


def run(args: argparse.Namespace) -> int:
    recording_format(args.output)  # reject a bad extension before any work
    rec = import_foreign(args.foreign, import_options(args))
    write_recording(rec, args.output)
    how = next((word for word in ("resampled", "retimed") if f"{word}_from" in rec.meta), "as sampled")
    rate_hz = float(rec.meta["sample_rate_hz"])
    print(f"{args.output}: {len(rec)} rows at {rate_hz:.6g} Hz ({how}) from {args.foreign}")
    return 0
