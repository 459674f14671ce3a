"""``trainer`` command line: dispatches to one module per sub-command in :mod:`trainer.commands`."""

from __future__ import annotations

import argparse
import importlib
import sys

from trainer import __version__
from trainer.errors import OneLineArgumentParser, run_cli
from trainer.heap import keep_freed_memory
from trainer.output_lock import command_outputs_locked

# Sub-command name -> module in trainer.commands that defines add_parser() and run().
COMMANDS: dict[str, str] = {
    "simulate": "simulate_cmd",
    "import": "import_cmd",
    "fit": "fit_cmd",
    "evaluate": "evaluate_cmd",
    "compare": "compare_cmd",
    "diagnose": "diagnose_cmd",
    "fleet": "fleet_cmd",
    "report": "report_cmd",
    "plan": "plan_cmd",
}


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineArgumentParser(
        prog="trainer",
        description="Temperature-drift compensation of MEMS IMUs (accelerometer, gyroscope and barometer channels).",
    )
    parser.add_argument("--version", action="version", version=f"mems-tdc {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, parser_class=OneLineArgumentParser)
    for module_name in COMMANDS.values():
        module = importlib.import_module(f"trainer.commands.{module_name}")
        module.add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    with command_outputs_locked(args):  # one writer per output
        return int(args.func(args) or 0)


def entry() -> None:
    keep_freed_memory()  # before any large allocation: the commands' work reuses freed memory
    sys.exit(run_cli(main))


if __name__ == "__main__":
    entry()
