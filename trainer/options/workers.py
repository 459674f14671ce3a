"""``--workers``: one rule for every command that runs tasks on Dask worker processes."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from contextlib import AbstractContextManager

    from trainer.fleet.cluster import TaskMap


def workers(text: str) -> int:
    """A whole number of worker processes, at least one."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive whole number of workers")
    return value


def add_workers_option(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, what: str, default: int | None
) -> None:
    """``--workers N``: ``what`` runs on N single-threaded processes (a Dask LocalCluster); the
    default ``None`` means one per core, ``1`` this process alone."""
    where = "one per core" if default is None else ("1: in this process" if default == 1 else str(default))
    parser.add_argument(
        "--workers",
        type=workers,
        default=default,
        metavar="N",
        help=f"{what} on N worker processes, one thread each, with the same results for any N (default {where})",
    )


def jobs_task_map(jobs: int | None) -> AbstractContextManager[TaskMap]:
    """Where ``trainer fit --method auto`` and ``trainer compare`` run a cross-validation's fits:
    ``--jobs N`` single-threaded workers, one per core when not given."""
    from trainer.fleet.cluster import default_workers, task_map  # Dask on use, not at --help

    return task_map(jobs or default_workers(), option="--jobs")
