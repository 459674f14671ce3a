"""``trainer fleet MANIFEST -o OUTDIR``: every unit of a manifest through the pipeline on Dask."""

from __future__ import annotations

import argparse

from trainer.options.workers import add_workers_option

EXIT_UNITS_FAILED = 1  # the fleet ran, but a unit failed or an export did not verify


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``trainer fleet``."""
    parser = subparsers.add_parser(
        "fleet",
        help="calibrate many units (import, diagnose, fit, evaluate, export, verify) on Dask; fleet report",
        description=(
            "For each unit of MANIFEST (CSV or TOML, see docs/fleet.md): import and validate, diagnose, fit "
            "each method, evaluate, export the C module and verify it; results in OUTDIR/units/ID/ and "
            "OUTDIR/report.md. Units already done with the same inputs and settings are skipped. Exit "
            "status 1 when a unit failed or an export did not verify."
        ),
    )
    parser.add_argument("manifest", metavar="MANIFEST", help="fleet manifest, .toml or .csv")
    parser.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="output directory")
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="an existing Dask scheduler (tcp://host:8786); default: a LocalCluster on this machine",
    )
    add_workers_option(parser, "the units", None)
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from trainer.fleet.report import FAIL
    from trainer.fleet.run import run_fleet

    fleet = run_fleet(
        args.manifest, args.output, scheduler=args.scheduler, workers=args.workers, progress=not args.quiet
    )
    import json

    summary = json.loads((fleet.out_dir / "fleet.json").read_text(encoding="utf-8"))
    verdicts = [u["sign_off"] for u in summary["units"]]
    counts = ", ".join(f"{verdicts.count(v)} {v}" for v in ("PASS", "REVIEW", FAIL))
    print(
        f"{len(verdicts)} units ({len(fleet.computed)} computed, {len(fleet.skipped)} already done): {counts}; "
        f"report {fleet.report}"
    )
    for unit in summary["units"]:
        if unit["sign_off"] != "PASS":
            why = "; ".join(unit["errors"] or unit["failed"] or unit["review"])
            print(f"  {unit['id']}: {unit['sign_off']} ({why})")
    return EXIT_UNITS_FAILED if FAIL in verdicts else 0
