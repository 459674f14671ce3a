"""What ``trainer fit`` prints and checks around ``--method auto`` (shared by one channel and many)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from trainer import methods
from trainer.selection import AUTO, record_lines
from trainer.train_stats import TrainStats


def checked_method(name: str) -> methods.Method:
    """The method whose training checks apply (auto: the cubic's temperature span, its simplest fit)."""
    return methods.get(methods.CUBIC if name == AUTO else name)


def progress_log(args: argparse.Namespace) -> Any:
    """Progress lines on stderr (a cross-validation fits every candidate once per segment)."""
    if getattr(args, "quiet", False):
        return None
    return lambda message: print(message, file=sys.stderr, flush=True)


def print_selection(stats: TrainStats) -> None:
    """The table that chose an auto model (from the checkpoint's record), and the choice in one line."""
    record = stats.selection
    if record is not None:
        for line in record_lines(record):
            print(line)
