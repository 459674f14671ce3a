"""``codegen`` command line: ``export`` a model.pt to C99, ``verify`` the C against the golden model."""

from __future__ import annotations

import argparse
import json
import sys

from codegen import __version__
from codegen.flightparams import EXTENSIONS
from codegen.quantize import SCHEDULES
from trainer.errors import OneLineArgumentParser, UserError, run_cli

EXIT_MISMATCH = 1


def _export(args: argparse.Namespace) -> int:
    if args.format != "c":
        if args.schedule != "step":
            raise UserError("--schedule applies to the C module (--format c), not to parameter files")
        return _export_params(args)
    for option, given in (
        ("--channel", args.channel),
        ("--device-id", args.device_id),
        ("--keep-constant", args.keep_constant),
    ):
        if given not in (None, False):
            raise UserError(f"{option} applies to --format px4-params/ardupilot-parm, not to the C module")
    if len(args.model) != 1:
        raise UserError(f"--format c renders one model per module; {len(args.model)} given")
    from codegen.export import export, manifest_name

    model, files = export(
        args.model[0], args.out_dir, name=args.name, accel_limit_g=args.accel_limit_g, schedule=args.schedule
    )
    name = next(f for f in files if f.endswith(".manifest.json"))[: -len(".manifest.json")]
    sizes = json.loads(files[manifest_name(name)])["sizes"]
    print(
        f"wrote {args.out_dir}/{{{', '.join(files)}}}: method {model.checkpoint.method}, "
        f"flash tables {sizes['flash_table_bytes']} B, state RAM {sizes['ram_state_bytes']} B, "
        f"model sha256:{model.sha256[:16]}..."
    )
    for note in model.notes:
        print(f"{model.checkpoint.method}: {note}")
    return 0


def _export_params(args: argparse.Namespace) -> int:
    """Flight-stack parameter files: one per command, all models' channels in it."""
    from codegen.export import write_files_atomically
    from codegen.flightparams import load_channel_cubic, render
    from codegen.render import validate_name

    if len(args.model) > 1 and (args.channel is not None or args.device_id is not None):
        raise UserError("--channel and --device-id name the channel of a single model; give one model")
    name = (
        validate_name(args.name)
        if args.name
        else ("px4_thermal" if args.format == "px4-params" else "ardupilot_tcal")
    )
    channels = [
        load_channel_cubic(path, channel=args.channel, device_id=args.device_id) for path in args.model
    ]
    text = render(args.format, channels, keep_constant=args.keep_constant)
    file_name = name + EXTENSIONS[args.format]
    write_files_atomically({file_name: text}, args.out_dir)
    print(f"wrote {args.out_dir}/{file_name}: {', '.join(c.name for c in channels)} ({args.format})")
    return 0


def _verify(args: argparse.Namespace) -> int:
    from codegen.verify import report_lines, verify

    result = verify(
        args.model, args.out_dir, args.recording, name=args.name, cc=args.cc, table1=not args.no_table
    )
    for line in report_lines(result):
        print(line)
    if result.mismatches or not result.state_equal:
        print(
            f"error: the generated C differs from the golden model ({result.mismatches} samples)",
            file=sys.stderr,
        )
        return EXIT_MISMATCH
    return 0


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
    exp.add_argument(
        "--accel-limit-g",
        type=float,
        default=16.0,
        help="acceleration full scale in g; the front end clamps beyond it (default 16)",
    )
    exp.add_argument(
        "--schedule",
        choices=SCHEDULES,
        default="step",
        help="DLSTMs: step runs the network on the sample that ends its window (default); spread splits it "
        "into tasks over the samples of the decimation period (worst sample about 2x the average, the "
        "estimate takes effect D - 1 samples later)",
    )
    exp.add_argument(
        "--format",
        choices=("c", *EXTENSIONS),
        default="c",
        help="c: the fixed-point C module (default); px4-params: a QGroundControl .params file of TC_*; "
        "ardupilot-parm: a .parm file of INS_TCALn_* (cubic models only)",
    )
    exp.add_argument(
        "--channel", help="parameter files: the sensor axis of the model (default: as fitted), e.g. accel0_z"
    )
    exp.add_argument(
        "--device-id", type=int, help="px4-params: the sensor's device id (default: as imported)"
    )
    exp.add_argument(
        "--keep-constant",
        action="store_true",
        help="px4-params: write the model's constant term as X0 (default 0: the ordinary calibration owns it)",
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
    ver.add_argument("--no-table", action="store_true", help="skip the Table 1 comparison (saves a few s)")
    ver.set_defaults(func=_verify)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


def entry() -> None:
    sys.exit(run_cli(main))


if __name__ == "__main__":
    entry()
