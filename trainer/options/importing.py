"""``trainer import``'s options: their declaration and the import settings they mean.

``trainer import`` adds them to its parser; a fleet manifest's ``import`` text is parsed by the
same declaration (:mod:`trainer.fleet.options`), so an option means the same in both.
"""

from __future__ import annotations

import argparse
import math

from trainer.data.csv_table import DELIMITER_NAMES
from trainer.data.flightlog import A_KIND
from trainer.data.flightlog_import import DEFAULT_CHANNEL, LogImportOptions
from trainer.data.importer import (
    ACCEL_UNIT_TO_MG,
    BARO_UNIT_TO_PA,
    FILL_TEMP_MODES,
    GRAVITY_MODES,
    GYRO_UNIT_TO_DPS,
    PRESETS,
    TEMP_UNIT_OFFSET_C,
    TIME_UNIT_SECONDS,
    ImportOptions,
    options_with_preset,
)
from trainer.data.plausibility import ACCEPT_OPTION
from trainer.errors import UserError
from trainer.options.channels import add_channels_option

# Options that map the columns of a delimited file; a flight log names its channels itself.
TEXT_ONLY_OPTIONS = (
    "preset",
    "delimiter",
    "time",
    "time_unit",
    "rate",
    "temp",
    "accel",
    "accel_unit",
    "extra_axes",
    "temp_unit",
    "decimal_comma",
    "channel_map",
    "gyro_unit",
    "baro_unit",
)

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
    """``--resample``: auto, none or a rate inside the plausible 0.1 Hz .. 100 kHz (0.0001 Hz gave a
    one-row recording)."""
    from trainer.data.plausibility import RATE_MAX_HZ, RATE_MIN_HZ

    if text in ("auto", "none"):
        return text
    rate_hz = _positive_hz(text)
    if not RATE_MIN_HZ <= rate_hz <= RATE_MAX_HZ:
        raise argparse.ArgumentTypeError(f"{text!r} Hz is outside {RATE_MIN_HZ:g} .. {RATE_MAX_HZ:g} Hz")
    return rate_hz


def _sensor_name(text: str) -> str:
    """``--sensor``: one line of metadata (a line break would end the header line it is written on)."""
    if not text.strip() or any(ord(c) < 32 for c in text):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a one-line name (no line breaks or control characters)"
        )
    return text


def _channel_map(text: str) -> dict[str, str]:
    """``accel0_x=COL,gyro0_x=COL,...``: recording-format channel names to the file's columns."""
    from trainer.data.flightlog import CHANNEL_NAME

    mapping: dict[str, str] = {}
    for item in text.split(","):
        name, sep, column = (part.strip() for part in item.partition("="))
        if not sep or not column or not CHANNEL_NAME.fullmatch(name):
            raise argparse.ArgumentTypeError(
                f"{item!r} is not CHANNEL=COLUMN (channels: accelN_x|y|z, gyroN_x|y|z, baroN)"
            )
        if name in mapping:
            raise argparse.ArgumentTypeError(f"{name} is mapped twice ({mapping[name]} and {column})")
        mapping[name] = column
    return mapping


def _axes(text: str) -> tuple[str, ...]:
    names = tuple(name.strip() for name in text.split(","))
    if len(names) != 3 or not all(names):
        raise argparse.ArgumentTypeError(f"{text!r} is not three column names X,Y,Z")
    return names


def add_import_arguments(parser: argparse.ArgumentParser) -> None:
    """Add every ``trainer import`` option; options left out fall back to the preset, then to defaults."""
    parser.add_argument(
        "foreign", metavar="FOREIGN", help="delimited file (with a header line) or flight log"
    )
    parser.add_argument("-o", "--output", metavar="OUT", help="output recording, .csv or .npz")
    parser.add_argument(
        "--channel",
        metavar="NAME",
        help=f"flight logs: the channel that becomes accel_mg, in its own unit (default {DEFAULT_CHANNEL}); "
        "each sensor instance is its own recording, several go to OUT_<instance>.ext",
    )
    add_channels_option(
        parser,
        "keep the data column (with the preset's units converted to mg, deg/s, Pa) and its temperature",
    )
    parser.add_argument(
        "--list-channels", action="store_true", help="flight logs: print every channel of the log and stop"
    )
    parser.add_argument("--preset", choices=sorted(PRESETS), help="column mapping of a known logger")
    parser.add_argument("--delimiter", type=_delimiter, help="tab, comma or semicolon (default: sniffed)")
    parser.add_argument("--time", metavar="COL", help="time column")
    parser.add_argument("--time-unit", choices=list(TIME_UNIT_SECONDS), help="unit of --time (default s)")
    parser.add_argument("--rate", type=_positive_hz, metavar="HZ", help="sample rate for --time-unit index")
    parser.add_argument("--temp", metavar="COL", help="sensor temperature column")
    parser.add_argument("--temp-unit", choices=list(TEMP_UNIT_OFFSET_C), help="unit of --temp (default degC)")
    parser.add_argument(
        "--fill-temp",
        choices=FILL_TEMP_MODES,
        help="an empty temperature field (a slower channel) repeats the previous reading",
    )
    parser.add_argument(
        "--decimal-comma", action="store_true", help="numbers are written 1,5 (tab or semicolon delimiter)"
    )
    parser.add_argument("--accel", metavar="COL", help="the axis to compensate (becomes accel_mg)")
    parser.add_argument(
        "--accel-unit",
        choices=list(ACCEL_UNIT_TO_MG),
        help="unit of the accelerometer columns: required without a --preset (no default: m/s^2 read as mg looks plausible)",
    )
    parser.add_argument(
        "--extra-axes", type=_axes, metavar="X,Y,Z", help="columns for accel_x_mg, accel_y_mg, accel_z_mg"
    )
    parser.add_argument(
        "--channel-map",
        type=_channel_map,
        metavar="CH=COL,...",
        help="delimited files: the columns of the channels --channels picks, e.g. accel0_x=ax,gyro0_x=gx",
    )
    parser.add_argument(
        "--gyro-unit",
        choices=list(GYRO_UNIT_TO_DPS),
        help="unit of gyro columns: required when --channel-map maps a gyroscope (no default: both look plausible)",
    )
    parser.add_argument(
        "--baro-unit",
        choices=list(BARO_UNIT_TO_PA),
        help="unit of baro columns: required when --channel-map maps a barometer (no default: both look plausible)",
    )
    parser.add_argument(
        "--remove-gravity", choices=GRAVITY_MODES, help="subtract +-1 g (nominal) or the mean from accel_mg"
    )
    parser.add_argument("--sensor", type=_sensor_name, metavar="NAME", help="sensor name for the metadata")
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
    parser.add_argument(
        ACCEPT_OPTION,
        action="store_true",
        help="warn instead of refusing implausible units, rates or temperatures",
    )


def log_import_options(args: argparse.Namespace, kind: str) -> LogImportOptions:
    """The parsed ``trainer import`` options of a flight log (``trainer fleet`` reuses it); a
    delimited file's column option is refused in one line."""
    for name in TEXT_ONLY_OPTIONS:
        if getattr(args, name) not in (None, False):
            option = "--" + name.replace("_", "-")
            raise UserError(
                f"{args.foreign}: {option} does not apply to {A_KIND[kind]} log (its channels carry "
                f"their units and temperatures); choose the axis with --channel"
            )
    resample = None if args.resample == "none" else args.resample
    return LogImportOptions(
        channel=args.channel,
        remove_gravity=args.remove_gravity or "none",
        sensor=args.sensor,
        resample=resample,
        retime=args.retime,
        fill_temp=args.fill_temp,
        channels=args.channels,
    )


def import_options(args: argparse.Namespace) -> ImportOptions:
    """The parsed ``trainer import`` options of a delimited file (``trainer fleet`` reuses it)."""
    if getattr(args, "channel_map", None) and not getattr(args, "channels", None):
        raise UserError("--channel-map maps the channels --channels picks: give --channels too (e.g. all)")
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
        temp_unit=args.temp_unit,
        decimal_comma=args.decimal_comma or None,
        fill_temp=args.fill_temp,
        channels=getattr(args, "channels", None),
        channel_map=getattr(args, "channel_map", None),
        gyro_unit=getattr(args, "gyro_unit", None),
        baro_unit=getattr(args, "baro_unit", None),
    )
