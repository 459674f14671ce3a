"""``trainer plan``: design the chamber program that identifies the target physics (docs/plan.md)."""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from trainer.options.seed import seed
from trainer.options.workers import add_workers_option
from trainer.plan.limits import ChamberLimits
from trainer.plan.summary import Target

if TYPE_CHECKING:
    from trainer.physics.config import PhysicsConfig
    from trainer.plan.priors import FittedModel

LIMITS, TARGET = ChamberLimits(), Target()
SENSOR_CONFIG = "realistic.toml"  # the packaged sensor of the sizes measured on the bundled run
DEFAULT_DRAWS, DEFAULT_SCREEN, DEFAULT_RATE_HZ = 20, 3, 1.0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``trainer plan``."""
    p = subparsers.add_parser(
        "plan",
        help="design the chamber program that identifies lag, rate and branch offset (Monte Carlo proof)",
        description=(
            "Choose the shortest chamber program within the chamber's limits on which the physics compensator "
            "identifies the target effects and beats the cubic, proved by a seeded Monte Carlo against the "
            "standard profiles. See docs/plan.md."
        ),
    )
    p.add_argument(
        "-o",
        "--out",
        required=True,
        metavar="DIR",
        help="output directory (program.toml, setpoints.csv, program.png, report.md)",
    )
    what = p.add_argument_group("targets (default: lag, rate and branch offset of the bundled run's sizes)")
    what.add_argument(
        "--targets",
        metavar="FILE",
        help="a TOML of prior ranges, a trainer diagnose --json document, or a fitted physics model.pt "
        "(its effects, +-30 %% around their fitted sizes, on its channel, with its temperature polynomial)",
    )
    what.add_argument(
        "--effects",
        metavar="SPEC",
        help="e.g. thermal_lag:tau_s=90..150,temp_rate (an effect alone: the bundled prior)",
    )
    sensor = p.add_argument_group("sensor")
    sensor.add_argument(
        "--sim",
        metavar="CONFIG.toml",
        help=f"the sensor's physics besides the targets (default: the packaged {SENSOR_CONFIG})",
    )
    sensor.add_argument(
        "--channel",
        metavar="NAME",
        help="plan for this channel of the --sim (gyro0_x: its [channels.gyro0_x] table; default the "
        "accelerometer, or a --targets model's channel)",
    )
    sensor.add_argument(
        "--noise-from",
        metavar="RECORDING",
        help="measure the white noise on a recording (slow noise scaled with it)",
    )
    chamber = p.add_argument_group("chamber limits")
    chamber.add_argument(
        "--range",
        nargs=2,
        type=float,
        default=(LIMITS.low_c, LIMITS.high_c),
        metavar=("LOW_C", "HIGH_C"),
        help="set-point range (default %(default)s)",
    )
    chamber.add_argument(
        "--max-rate",
        type=float,
        default=LIMITS.max_rate_c_per_min,
        metavar="C_PER_MIN",
        help="fastest ramp (default %(default)s)",
    )
    chamber.add_argument(
        "--settling",
        type=float,
        default=LIMITS.settling_s,
        metavar="S",
        help="hold after every ramp, and soak before the first (default %(default)s)",
    )
    chamber.add_argument(
        "--max-hours",
        type=float,
        default=LIMITS.max_duration_s / 3600,
        metavar="H",
        help="longest program (default %(default)s)",
    )
    proof = p.add_argument_group("Monte Carlo")
    proof.add_argument(
        "--draws", type=int, default=DEFAULT_DRAWS, help="draws per profile (default %(default)s)"
    )
    proof.add_argument(
        "--screen-draws",
        type=int,
        help=f"draws that screen a candidate (default {DEFAULT_SCREEN}, at most --draws)",
    )
    proof.add_argument("--seed", type=seed, default=0, help="seed of the draws (default %(default)s)")
    proof.add_argument(
        "--rate",
        type=float,
        default=DEFAULT_RATE_HZ,
        metavar="HZ",
        help="simulated sample rate (default %(default)s)",
    )
    add_workers_option(proof, "the draws", 1)
    proof.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler (tcp://host:8786)")
    proof.add_argument("--no-standard", action="store_true", help="skip the standard profiles' rows")
    goal = p.add_argument_group("target")
    goal.add_argument(
        "--identify-rate",
        type=float,
        default=TARGET.identify_rate,
        help="share of draws (default %(default)s)",
    )
    goal.add_argument(
        "--tolerance",
        type=float,
        default=TARGET.tolerance,
        help="relative parameter error (default %(default)s)",
    )
    goal.add_argument(
        "--vs-cubic",
        type=float,
        default=TARGET.vs_cubic,
        help="physics' drift left over the cubic's (default %(default)s)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def _channel(
    args: argparse.Namespace, fitted: FittedModel | None, diagnosed: str | None = None
) -> tuple[str | None, str]:
    """The planned channel's table name in the --sim (None: the accelerometer's physics) and unit:
    --channel, else the channel of the --targets model, or of the --targets diagnosis (``diagnosed``)."""
    from trainer.data.channels import unit_of_channel_name
    from trainer.data.flightlog import parse_channel
    from trainer.errors import UserError
    from trainer.physics.catalogue.units import CATALOGUE_UNIT

    made_on = fitted.channel if fitted is not None else diagnosed
    name = args.channel if args.channel is not None else made_on
    if name is None:
        return None, CATALOGUE_UNIT
    if parse_channel(name) is None:
        raise UserError(f"--channel {name!r}: not a channel name (accel0_z, gyro0_x, baro0)")
    if made_on is not None and name != made_on:
        what = "model was fitted" if fitted is not None else "diagnosis was made"
        raise UserError(f"--channel {name} but the --targets {what} on {made_on}; give one")
    unit = unit_of_channel_name(name)
    if fitted is not None and fitted.unit != unit:
        raise UserError(
            f"--channel {name} is in {unit} but the --targets model's effects are in {fitted.unit} "
            "(a model of another sensor); give a model fitted on this channel"
        )
    return (None if unit == CATALOGUE_UNIT else name), unit


def _base(args: argparse.Namespace, channel: str | None, fitted: FittedModel | None) -> PhysicsConfig:
    """The simulated sensor: --sim with only the planned channel's table, the model's polynomial."""
    from importlib import resources

    from trainer.errors import UserError
    from trainer.physics.config import ChannelConfig, load_config
    from trainer.plan.montecarlo import merged_effects

    path = args.sim or str(resources.files("trainer.physics").joinpath(SENSOR_CONFIG))
    cfg = load_config(path)
    own = next((c for c in cfg.channels if c.name == channel), None)
    if channel is not None and own is None:
        raise UserError(
            f"--channel {channel}: {path} has no [channels.{channel}] table (its noise and temperature "
            "polynomial); give a --sim with one"
        )
    cfg = replace(cfg, channels=() if own is None else (own,))
    if fitted is not None and fitted.bias_poly is not None:
        poly = (fitted.bias_poly,)
        if own is None:
            cfg = replace(cfg, effects=merged_effects(cfg.effects, poly))
        else:
            cfg = replace(
                cfg, channels=(ChannelConfig(own.name, merged_effects(own.effects, poly), own.noise),)
            )
    return cfg if args.noise_from is None else _with_noise(cfg, args.noise_from, channel)


def _with_noise(cfg: PhysicsConfig, path: str, channel: str | None) -> PhysicsConfig:
    """The recording's white-noise density (of the planned channel); the slow terms scaled by the same
    factor (their shares kept)."""
    from trainer.data.channels import (
        UNIT_LABELS,
        channel_unit,
        channel_view,
        select_channels,
        unit_of_channel_name,
    )
    from trainer.data.recording_io import read_recording
    from trainer.diagnose.blocks import white_noise_density
    from trainer.errors import UserError
    from trainer.physics.catalogue.white_noise import DEFINITION as WHITE_NOISE
    from trainer.physics.config import ChannelConfig, NoiseConfig

    rec = read_recording(path)
    if channel is not None:
        rec = channel_view(rec, select_channels(rec, (channel,))[0])
    planned, measured_unit = unit_of_channel_name(channel), channel_unit(rec)
    if measured_unit != planned:
        raise UserError(
            f"--noise-from {path}: its data are in {UNIT_LABELS[measured_unit]} ({rec.meta.get('channel')}), the "
            f"planned channel's in {UNIT_LABELS[planned]}: give a recording of the planned sensor, or --channel"
        )
    measured = white_noise_density(rec.accel_mg, rec.sample_rate_hz)
    own = cfg.channels[0] if channel is not None else None
    terms = own.noise if own is not None else cfg.noise
    white = next((n for n in terms if n.identifier == WHITE_NOISE.identifier), None)
    if white is None or not white.params["n_mg_rt_s"] > 0:
        table = f"[channels.{channel}.noise.white_noise]" if channel else "[noise.white_noise]"
        raise UserError(f"--noise-from {path}: the --sim has no white noise to scale from; add {table}")
    factor = measured / white.params["n_mg_rt_s"]
    noise = tuple(NoiseConfig(n.identifier, {k: v * factor for k, v in n.params.items()}) for n in terms)
    if own is None:
        return replace(cfg, noise=noise)
    return replace(cfg, channels=(ChannelConfig(own.name, own.effects, noise),))


def _stderr(line: str) -> None:
    import sys

    print(line, file=sys.stderr, flush=True)


# A lower bound of what a draw costs (it simulates and diagnoses a program: docs/plan.md's 20 draws of
# the planned program and its alternatives took 24 min on the 2-core VM), and the columns a draw simulates
SECONDS_PER_DRAW = 1.0
PLAN_COLUMNS = 4


def _check(args: argparse.Namespace) -> None:
    from trainer.budget import check_rows, check_time
    from trainer.errors import UserError
    from trainer.options.numbers import check_finite

    if args.screen_draws is None:
        args.screen_draws = min(DEFAULT_SCREEN, args.draws)
    for name, value, low in (
        ("--draws", args.draws, 1),
        ("--screen-draws", args.screen_draws, 1),
    ):
        if value < low:
            raise UserError(f"{name} must be >= {low}, got {value}")
    if args.screen_draws > args.draws:
        raise UserError(
            f"--screen-draws {args.screen_draws} is more than --draws {args.draws}: screening is the first "
            "draws of a profile's proof"
        )
    if not (args.rate > 0 and math.isfinite(args.rate)):
        raise UserError(f"--rate must be a finite number > 0 Hz, got {args.rate:g}")
    check_finite("--max-hours", args.max_hours, inclusive=False)
    # each draw simulates and diagnoses a program of up to --max-hours: a typo is one line, not a run of years
    check_rows(
        args.max_hours * 3600 * args.rate,
        PLAN_COLUMNS,
        f"--max-hours {args.max_hours:g} at --rate {args.rate:g}",
        "give fewer hours or a lower --rate",
    )
    check_time(
        args.draws * SECONDS_PER_DRAW,
        f"--draws {args.draws}",
        "give fewer draws (a profile's proof is tens of draws)",
    )
    if not 0 < args.identify_rate <= 1:
        raise UserError(f"--identify-rate must be a share in (0, 1], got {args.identify_rate:g}")
    for name, value in (("--tolerance", args.tolerance), ("--vs-cubic", args.vs_cubic)):
        check_finite(name, value, inclusive=False)


def run(args: argparse.Namespace) -> int:
    from trainer.atomic_dir import atomic_directory, check_output_directory
    from trainer.errors import UserError
    from trainer.plan import outputs, priors
    from trainer.plan.chamber import validation_program, violations
    from trainer.plan.design import choose
    from trainer.plan.montecarlo import DrawTask, runner
    from trainer.plan.programs import Program, candidates, standard
    from trainer.plan.summary import summarise

    _check(args)
    check_output_directory(args.out)
    fitted = None
    if args.targets is not None and args.targets.lower().endswith(".pt"):
        if args.effects is not None:
            raise UserError("--targets and --effects both give the targets; give one")
        fitted = priors.from_model(Path(args.targets))
    diagnosed = None
    if args.targets is not None and args.targets.lower().endswith(".json"):
        diagnosed = priors.diagnosis_channel(Path(args.targets))
    channel, unit = _channel(args, fitted, diagnosed)
    targets = fitted.priors if fitted is not None else priors.load(args.targets, args.effects, unit)
    limits = ChamberLimits(args.range[0], args.range[1], args.max_rate, args.settling, args.max_hours * 3600)
    target = Target(args.identify_rate, args.tolerance, args.vs_cubic)
    base = _base(args, channel, fitted)
    validation = validation_program(limits)
    options = candidates(limits)
    if not options:
        raise UserError(
            f"--max-hours {args.max_hours:g}: no candidate program fits (one cycle with settling needs more)"
        )

    def make(program: Program, indices: range) -> list[DrawTask]:
        return [
            DrawTask(base, targets, program, validation, args.seed, i, args.rate, channel) for i in indices
        ]

    with runner(args.workers, args.scheduler, not args.no_progress) as pool:
        choice = choose(
            options, make, pool, targets, target, draws=args.draws, screen=args.screen_draws, log=_stderr
        )
        others = () if args.no_standard else standard(limits)
        rows = [
            summarise(p.name, p.duration_s, pool.map(make(p, range(args.draws)), p.name), targets, target)
            for p in others
        ]
    assert not violations(choice.program, limits), "a candidate is built within the limits"
    with atomic_directory(args.out) as staging:
        (staging / outputs.PROGRAM_TOML).write_text(
            outputs.program_toml(base, targets, choice.program, args.rate, channel), encoding="utf-8"
        )
        (staging / outputs.SETPOINTS_CSV).write_text(outputs.setpoints_csv(choice.program), encoding="utf-8")
        outputs.plot(staging / outputs.PLOT_PNG, choice.program, others, validation)
        text = outputs.report(
            choice,
            rows,
            targets,
            limits,
            target,
            validation,
            seed=args.seed,
            rate_hz=args.rate,
            channel=channel,
        )
        (staging / outputs.REPORT_MD).write_text(text, encoding="utf-8")
    verdict = choice.summary.verdict_text(target)
    print(f"planned: {choice.program.name}, {choice.program.duration_s / 3600:.2f} h: {verdict}")
    print(outputs.table([choice.summary, *rows], targets, target))
    print(f"wrote {args.out}/{outputs.REPORT_MD}")
    return 0
