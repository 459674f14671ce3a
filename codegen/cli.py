"""``codegen`` command line: ``export`` a model.pt to C99, ``verify`` the C against the golden model."""

from __future__ import annotations

import argparse
import json
import sys

from codegen import __version__
from codegen.family import schedules
from codegen.flightparams import EXTENSIONS
from codegen.input_limits import add_raw_limit_options
from trainer.errors import OneLineArgumentParser, UserError, run_cli
from trainer.options.channels import add_channels_option
from trainer.output_lock import command_outputs_locked

# codegen verify's exit status (0: passed; 2: a usage error, trainer.errors): the C differs from its
# golden model; else the C equals it but its integer arithmetic is over the error budget
EXIT_MISMATCH = 1
EXIT_OVER_BUDGET = 3


def _export(args: argparse.Namespace) -> int:
    channels = args.channels is not None
    if channels:
        from trainer.options.channels import model_files

        args.model = [str(path) for directory in args.model for path in model_files(directory, args.channels)]
    _check_models(args.model)
    # --channels (any number of channels, one too) or several models: the IMU module, one API for every
    # channel list; a one-channel module is exported from the model file itself
    if (
        args.format == "calibration-blob"
        or args.blob
        or (args.format == "c" and (channels or len(args.model) > 1))
    ):
        return _export_imu(args)
    if args.format != "c":
        if args.rate is not None:
            raise UserError("--rate applies to the C module (--format c); parameter files have no time base")
        if args.schedule != "step":
            raise UserError("--schedule applies to the C module (--format c), not to parameter files")
        from codegen.input_limits import RAW_INPUT_LIMITS, given_raw_limits

        for unit in given_raw_limits(args):
            option = RAW_INPUT_LIMITS[unit].option
            raise UserError(f"{option} applies to the C module (--format c), not to parameter files")
        if args.format == "ardupilot-parm" and args.device_id is not None:
            raise UserError(
                "--device-id applies to --format px4-params: ArduPilot's INS_TCAL1..3 apply by IMU index "
                "(accel0/gyro0 -> INS_TCAL1, accel1/gyro1 -> INS_TCAL2), not by device id"
            )
        return _export_params(args)
    _refuse_parameter_options(args)
    if len(args.model) != 1:
        raise UserError(f"--format c renders one model per module; {len(args.model)} given")
    from codegen.export import export, manifest_name
    from codegen.input_limits import given_raw_limits
    from codegen.rate import parse_rate_hz

    rate = None if args.rate is None else parse_rate_hz(args.rate)
    model, files = export(
        args.model[0],
        args.out_dir,
        name=args.name,
        raw_limits=given_raw_limits(args),
        rate_millihz=rate,
        schedule=args.schedule,
    )
    name = next(f for f in files if f.endswith(".manifest.json"))[: -len(".manifest.json")]
    sizes = json.loads(files[manifest_name(name)])["sizes"]
    print(
        f"wrote {args.out_dir}/{{{', '.join(files)}}}: method {model.name}, "
        f"flash tables {sizes['flash_table_bytes']} B, state RAM {sizes['ram_state_bytes']} B, "
        f"model sha256:{model.sha256[:16]}..."
    )
    for note in model.notes:
        print(f"{model.name}: {note}")
    return 0


def _refuse_parameter_options(args: argparse.Namespace) -> None:
    """The parameter files' options, given for a C module (one channel's or the IMU module)."""
    for option, given, formats in (
        ("--channel", args.channel, "px4-params/ardupilot-parm"),
        ("--device-id", args.device_id, "px4-params"),
        ("--keep-constant", args.keep_constant, "px4-params"),
    ):
        if given not in (None, False):
            raise UserError(f"{option} applies to --format {formats}, not to the C module")


def _check_models(paths: list[str]) -> None:
    """Each model's record, read once: a model fitted with ``--holdout`` that left more than no
    compensation on the part it held out (``train_stats.held_out``, the sign-off's guard) must not reach
    firmware, refused in one line before anything is written; then, one line each, the models that are
    the identity because auto found no compensation that helps."""
    from trainer.checkpoint import load_checkpoint
    from trainer.data.channels import UNIT_LABELS
    from trainer.scoring.fit_holdout import held_out_guard
    from trainer.selection import identity_note
    from trainer.train_stats import TrainStats

    records = [(path, TrainStats.of_checkpoint(load_checkpoint(path))) for path in paths]
    refused = []
    for path, stats in records:
        guard = held_out_guard(stats, path, UNIT_LABELS.get(stats.unit or "mg", stats.unit or "mg"))
        if guard is not None and not guard.ok:
            refused.append((path, guard.detail))
    if refused:
        path, detail = refused[0]
        others = f" (likewise {', '.join(p for p, _ in refused[1:])})" if len(refused) > 1 else ""
        raise UserError(
            f"{path}: {detail}{others}: a compensator worse than none must not reach firmware (refit it on a "
            "whole cycle, e.g. trainer fit --method auto, which leaves a channel uncompensated where nothing helps)"
        )
    for path, stats in records:
        note = identity_note(stats, path)
        if note is not None:
            print(note)


def _export_imu(args: argparse.Namespace) -> int:
    """``--channels`` or several models: one IMU module (docs/imu-module.md) and/or its calibration blob."""
    from pathlib import Path

    from codegen.imu import export_imu
    from codegen.input_limits import given_raw_limits
    from codegen.rate import parse_rate_hz

    if args.format not in ("c", "calibration-blob"):
        raise UserError(f"--blob applies to --format c, not {args.format}")
    _refuse_parameter_options(args)
    if args.schedule != "step":
        raise UserError(
            "--schedule applies to a DLSTM's own module; the IMU module runs its DLSTM channels with step"
        )
    blob_only = args.format == "calibration-blob"
    imu, written = export_imu(
        [Path(p) for p in args.model],
        args.out_dir,
        name=args.name or "imu_tdc",
        raw_limits=given_raw_limits(args),
        blob=args.blob,
        blob_only=blob_only,
        rate_millihz=None if args.rate is None else parse_rate_hz(args.rate),
    )
    what = "calibration blob" if blob_only else "data-only IMU module and blob" if args.blob else "IMU module"
    print(
        f"wrote {args.out_dir}/{{{', '.join(written)}}}: {what}, {len(imu.channels)} "
        f"channel{'' if len(imu.channels) == 1 else 's'} "
        f"({', '.join(f'{c.name} {c.model.name}' for c in imu.channels)}), "
        f"module id 0x{imu.module_id:08x}, calibration sha256:{imu.sha256[:16]}..."
    )
    for (
        channel
    ) in imu.channels:  # what each channel's own module says: its unit, the offset it removes, warnings
        for note in channel.model.notes:
            print(f"{channel.name}: {note.removeprefix(f'channel {channel.name}: ')}")
    return 0


def _export_params(args: argparse.Namespace) -> int:
    """Flight-stack parameter files: one per command, all models' channels in it."""
    from codegen.export import write_files_atomically
    from codegen.flightparams import NOTE, load_channel_cubics, render
    from codegen.render import validate_name

    per_sensor = args.device_id if isinstance(args.device_id, dict) else {}
    device_id = None if per_sensor else args.device_id
    if len(args.model) > 1 and (args.channel is not None or device_id is not None):
        raise UserError(
            "--channel and --device-id ID name the channel of a single model; give one model "
            "(or --device-id SENSOR=ID,... such as accel0=ID,gyro0=ID)"
        )
    name = (
        validate_name(args.name)
        if args.name
        else ("px4_thermal" if args.format == "px4-params" else "ardupilot_tcal")
    )
    channels = load_channel_cubics(args.model, channel=args.channel, device_id=device_id)
    if per_sensor:
        import dataclasses

        sensors = {f"{c.channel.sensor}{c.channel.instance}" for c in channels}
        unknown = sorted(set(per_sensor) - sensors)
        if unknown:
            raise UserError(
                f"--device-id {unknown[0]}=...: no model of that sensor (models: {', '.join(sorted(sensors))})"
            )
        channels = [
            dataclasses.replace(
                c, device_id=per_sensor.get(f"{c.channel.sensor}{c.channel.instance}", c.device_id)
            )
            for c in channels
        ]
    text = render(args.format, channels, keep_constant=args.keep_constant)
    file_name = name + EXTENSIONS[args.format]
    write_files_atomically({file_name: text}, args.out_dir)
    print(f"wrote {args.out_dir}/{file_name}: {', '.join(c.name for c in channels)} ({args.format})")
    for line in text.splitlines():
        if line.startswith(NOTE):
            print(line[len(NOTE) :])
    if args.format == "px4-params":
        from codegen.px4_republish import lag_bound_lines

        for line in lag_bound_lines(channels):
            print(line)
    return 0


def _verify_imu(args: argparse.Namespace) -> int:
    from pathlib import Path

    from codegen.imu_verify import imu_report_lines, verify_imu, write_imu_json
    from codegen.verify import check_module_dir
    from trainer.data.plausibility import check_scored
    from trainer.data.recording_io import read_recording
    from trainer.errors import check_output_path
    from trainer.options.channels import model_files

    if args.json:  # before the build, not after it; never over an input
        check_output_path(args.json, inputs=[args.model, args.recording])
    check_module_dir(Path(args.out_dir))
    rec = check_scored(read_recording(args.recording))
    models = model_files(args.model, args.channels)
    result = verify_imu(models, Path(args.out_dir), rec, name=args.name, cc=args.cc, cortex_m4=args.cortex_m4)
    for line in imu_report_lines(result):
        print(line)
    if args.json:
        write_imu_json(result, args.json)
    if not result.ok:
        print("error: the generated IMU module differs from the golden model", file=sys.stderr)
        return EXIT_MISMATCH
    return 0


def _verify(args: argparse.Namespace) -> int:
    if args.channels is not None:
        return _verify_imu(args)
    if args.cortex_m4:
        raise UserError("--cortex-m4 applies to an IMU module (--channels); see firmware_c/ for one channel")
    from pathlib import Path

    from codegen.imu_verify import imu_manifest

    if args.name is None and imu_manifest(Path(args.out_dir), None) is not None:
        raise UserError(
            f"{args.out_dir} holds an IMU module: verify it with --channels all (MODEL: the 'trainer fit "
            f"--channels' directory)"
        )
    from codegen.verify import report_lines, verify, write_json
    from trainer.errors import check_output_path

    if args.json:  # before the build, not after it; never over an input (it once replaced the recording)
        check_output_path(args.json, inputs=[args.model, args.recording])
    result = verify(
        args.model,
        args.out_dir,
        args.recording,
        name=args.name,
        cc=args.cc,
        table1=not args.no_table,
        resample=args.resample,
    )
    from trainer.data.channels import relabel_units

    for line in report_lines(result):
        print(relabel_units(line, result.unit))
    if args.json:
        write_json(result, args.out_dir, args.json)
    if result.mismatches or not result.state_equal:
        where = [f"{result.mismatches} output samples"] if result.mismatches else []
        where += [] if result.state_equal else ["the final state"]
        print(
            f"error: the generated C differs from the golden model ({' and '.join(where)})", file=sys.stderr
        )
        return EXIT_MISMATCH
    if not result.budget.met:
        from codegen.verify import ERROR_BUDGET_MAX_MG, ERROR_BUDGET_RMS_MG

        b = result.budget
        print(
            relabel_units(
                f"error: the quantised model is over the error budget: its integer arithmetic strays RMS "
                f"{b.arithmetic_rms_mg:.3g} mg, max {b.arithmetic_max_abs_mg:.3g} mg from the float model "
                f"(budget {ERROR_BUDGET_RMS_MG:g} mg RMS, {ERROR_BUDGET_MAX_MG:g} mg max; docs/codegen.md, "
                f'"Error budget"); the C equals its golden model',
                result.unit,
            ),
            file=sys.stderr,
        )
        return EXIT_OVER_BUDGET
    return 0


def _device_ids(text: str) -> int | dict[str, int]:
    """``ID`` (one model) or ``SENSOR=ID,...`` (sensor instances such as accel0, gyro0)."""
    import re

    if text.strip().isdigit():
        return int(text)
    ids = {}
    for item in text.split(","):
        match = re.fullmatch(r"\s*((?:accel|gyro|baro)[0-9])=([0-9]+)\s*", item)
        if match is None:
            raise argparse.ArgumentTypeError(f"{item!r} is not ID or SENSOR=ID (e.g. accel0=2490378)")
        if match.group(1) in ids:  # the last one would win silently
            raise argparse.ArgumentTypeError(f"{match.group(1)} is given twice")
        ids[match.group(1)] = int(match.group(2))
    return ids


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineArgumentParser(
        prog="codegen", description="Fixed-point C99 export of mems-tdc compensators."
    )
    parser.add_argument("--version", action="version", version=f"mems-tdc codegen {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineArgumentParser)

    exp = sub.add_parser(
        "export",
        help="quantise a model.pt and render NAME.h, NAME.c and a manifest, or write flight-stack parameters",
    )
    exp.add_argument(
        "model",
        nargs="+",
        help="checkpoint written by 'trainer fit' (model.pt); parameter files take several",
    )
    exp.add_argument(
        "-o", "--out-dir", required=True, help="output directory (created; its parent must exist)"
    )
    exp.add_argument("--name", help="C prefix and file name (default tdc_<method>); a C identifier")
    add_raw_limit_options(exp)  # --accel-limit-g, --gyro-limit-dps: one per row of codegen/input_limits.py
    add_channels_option(
        exp,
        "take the model from each MODEL directory (written by 'trainer fit --channels'); --format c renders "
        "one IMU module (docs/imu-module.md), whatever the number of channels: a one-channel module is "
        "exported from the model file itself",
    )
    exp.add_argument(
        "--blob",
        action="store_true",
        help="several channels: a data-only module that reads its tables from NAME.cal.bin (also written)",
    )
    exp.add_argument(
        "--rate",
        type=float,
        metavar="HZ",
        help="the firmware's sample rate: a model with a time base (DLSTM front end, physics filters) is "
        "re-derived for it exactly or refused; a model without one (cubic, PLA, physics without a filter) runs at "
        "any rate and is exported as trained (default: as trained)",
    )
    exp.add_argument(
        "--schedule",
        choices=schedules(),
        default="step",
        help="DLSTMs: step runs the network on the sample that ends its window (default); spread splits it "
        "into tasks over the samples of the decimation period (worst sample about 2x the average, the "
        "estimate takes effect D - 1 samples later)",
    )
    exp.add_argument(
        "--format",
        choices=("c", *EXTENSIONS, "calibration-blob"),
        default="c",
        help="c: the fixed-point C module (default; one IMU module with --channels or several models); px4-params: a "
        "QGroundControl .params file of TC_*; ardupilot-parm: a .parm file of INS_TCALn_* (cubic models only); "
        "calibration-blob: only NAME.cal.bin, a unit's tables for a data-only IMU module",
    )
    exp.add_argument(
        "--channel", help="parameter files: the sensor axis of the model (default: as fitted), e.g. accel0_z"
    )
    exp.add_argument(
        "--device-id",
        type=_device_ids,
        metavar="ID|SENSOR=ID,...",
        help="px4-params: the sensor's device id (default: as imported); several models: accel0=ID,gyro0=ID",
    )
    exp.add_argument(
        "--keep-constant",
        action="store_true",
        help="px4-params: write the model's constant term as X0 (default 0: the ordinary calibration owns it); "
        "a model fitted with 'trainer fit --offset relative' (the default) holds none and is refused: fit with "
        "--offset absolute to keep it",
    )
    exp.set_defaults(func=_export)

    ver = sub.add_parser(
        "verify", help="compile OUTDIR's C and compare it with the golden model on a recording"
    )
    ver.add_argument("model", help="the model.pt the module was exported from")
    ver.add_argument("out_dir", help="directory written by 'codegen export'")
    ver.add_argument("recording", help="recording (.csv or .npz) to stream through both")
    ver.add_argument("--name", help="module name when OUTDIR holds several")
    ver.add_argument("--cc", help="C compiler (default $CC, cc, gcc or clang)")
    ver.add_argument(
        "--resample",
        action="store_true",
        help="interpolate a recording of another rate onto the module's rate (a module exported with --rate)",
    )
    ver.add_argument("--json", metavar="PATH", help="also write the result as JSON (for 'trainer report')")
    ver.add_argument("--no-table", action="store_true", help="skip the Table 1 comparison (saves a few s)")
    add_channels_option(ver, "verify an IMU module (MODEL: the 'trainer fit --channels' directory)")
    ver.add_argument(
        "--cortex-m4", action="store_true", help="IMU module: also run it on a Cortex-M4 under QEMU"
    )
    ver.set_defaults(func=_verify)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    with command_outputs_locked(args):  # one writer per output
        return int(args.func(args) or 0)


def entry() -> None:
    sys.exit(run_cli(main))


if __name__ == "__main__":
    entry()
