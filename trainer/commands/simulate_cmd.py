"""``trainer simulate``: write a simulated oven recording with ground-truth columns."""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace

from trainer.data.plausibility import RATE_MAX_HZ, RATE_MIN_HZ
from trainer.data.recording_io import recording_format, write_recording
from trainer.errors import UserError
from trainer.options.seed import seed
from trainer.physics.config import load_config, with_overrides
from trainer.physics.input_presets import INPUT_PRESETS, input_preset
from trainer.physics.profiles import BUILTIN_PROTOCOLS
from trainer.physics.simulate import nominal_rows, simulate


def _positive(unit: str) -> type[float]:
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of {unit}")
        return value

    return parse  # type: ignore[return-value]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``trainer simulate``."""
    parser = subparsers.add_parser(
        "simulate",
        help="simulate an oven recording of a MEMS accelerometer, and of further channels (gyroscope, barometer) its configuration declares (with true_* ground truth)",
        description=(
            "Simulate the thermal-chamber recording of a MEMS accelerometer, and of the further channels "
            "(gyroscope, barometer) its physics configuration declares (default: the packaged default.toml). "
            "See docs/simulator.md."
        ),
    )
    parser.add_argument(
        "--protocol", choices=tuple(BUILTIN_PROTOCOLS), help="override the configured protocol"
    )
    parser.add_argument("--seed", type=seed, required=True, help="random seed (non-negative integer)")
    parser.add_argument("-o", "--output", required=True, help="output recording, .csv or .npz")
    parser.add_argument("--config", help="physics configuration TOML (default: the packaged default.toml)")
    parser.add_argument(
        "--duration",
        type=_positive("seconds"),
        metavar="S",
        help="time-compress the whole protocol to S seconds (short test recordings; ramps get steeper)",
    )
    parser.add_argument("--rate", type=_positive("Hz"), metavar="HZ", help="override sample_rate_hz")
    parser.add_argument(
        "--input",
        choices=INPUT_PRESETS,
        help="replace the configured true input by a built-in profile (steps: tilt sequence; motion: "
        "manoeuvres and vibration) to measure how much of a real signal a compensator keeps",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    recording_format(args.output)  # reject a bad extension before a long simulation
    cfg = with_overrides(
        load_config(args.config), protocol=args.protocol, duration_s=args.duration, sample_rate_hz=args.rate
    )
    rate_hz = cfg.recording.sample_rate_hz
    if not RATE_MIN_HZ <= rate_hz <= RATE_MAX_HZ:  # what import and fit would refuse as a time-unit mistake
        given = "--rate" if args.rate is not None else f"{cfg.source}: [recording] sample_rate_hz"
        raise UserError(
            f"{given} {rate_hz:g} Hz is outside the {RATE_MIN_HZ:g} Hz .. {RATE_MAX_HZ / 1e3:g} kHz that trainer fit "
            "and import accept: its recording could not be fitted"
        )
    rows = nominal_rows(cfg)
    if args.input:
        cfg = replace(cfg, input=input_preset(args.input, rows / cfg.recording.sample_rate_hz))
    started = time.perf_counter()
    rec = simulate(cfg, args.seed, progress=True)
    simulated = time.perf_counter() - started
    write_recording(rec, args.output)
    print(
        f"wrote {args.output}: {rows} rows, {cfg.protocol.name} ({rec.meta['segments']}), "
        f"seed {args.seed}, config {rec.meta['config_hash']}; simulated in {simulated:.2f} s",
        file=sys.stderr,
    )
    return 0
