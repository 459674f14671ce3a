"""``--offset`` and ``--tref``: the offset policy of temperature-driven methods, declared once.

``trainer fit`` and ``trainer compare`` add these options; the policy itself (what ``T_ref`` is,
what each mode removes, the 100 mg limit) lives in :mod:`trainer.reference`.
"""

from __future__ import annotations

import argparse

from trainer.reference import OFFSET_LIMIT_MG, OFFSET_MODES, OFFSET_OPTION, TREF_OPTION, OffsetPolicy


def add_offset_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        OFFSET_OPTION,
        choices=OFFSET_MODES,
        default="relative",
        help="temperature-driven methods: 'relative' (default) models the drift relative to its value at "
        f"T_ref and leaves the static offset to the accelerometer calibration; 'absolute' removes the "
        f"fitted constant too, refused above {OFFSET_LIMIT_MG:g} mg; 'absolute-unbounded' without that limit",
    )
    parser.add_argument(
        TREF_OPTION,
        type=float,
        metavar="DEGC",
        help="reference temperature in degC (default: mid-point of the training temperature range, "
        "PX4's TREF)",
    )


def policy_from_args(args: argparse.Namespace) -> OffsetPolicy:
    return OffsetPolicy(args.offset, args.tref)
