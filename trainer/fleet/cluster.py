"""Where the tasks run: an embedded ``LocalCluster`` by default, or an existing Dask cluster.

Each worker runs one task at a time per thread, and each task limits BLAS and torch to one
thread (:func:`one_thread`): with N workers on N cores, a task that spread its linear algebra over
every core would make N tasks fight for them (the finder alone ran 5-10 times slower that way,
see :mod:`trainer.diagnose.threads`).
"""

from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import wraps
from typing import Any, ParamSpec, TypeVar

from threadpoolctl import threadpool_limits

from trainer.errors import UserError

P = ParamSpec("P")
R = TypeVar("R")
CONNECT_TIMEOUT_S = 20.0
# Set for the embedded workers' processes before any library reads them.
ONE_THREAD_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


@contextmanager
def one_thread() -> Iterator[None]:
    """BLAS/OpenMP pools and torch's intra-op pool limited to one thread inside the block."""
    import torch

    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with threadpool_limits(limits=1):
            yield
    finally:
        torch.set_num_threads(previous)


def pinned(function: Callable[P, R]) -> Callable[P, R]:
    """Run ``function`` inside :func:`one_thread` (every fleet task is wrapped)."""

    @wraps(function)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with one_thread():
            return function(*args, **kwargs)

    return wrapper


def default_workers() -> int:
    return max(1, os.cpu_count() or 1)


@contextmanager
def open_client(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """A ``distributed.Client`` on ``scheduler`` (an address), else on a new ``LocalCluster``.

    ``workers`` is the LocalCluster's number of single-threaded worker processes (default: the
    machine's cores); with ``scheduler`` the cluster's own workers are used and ``workers`` must
    not be given.
    """
    from distributed import Client, LocalCluster

    if scheduler is not None:
        if workers is not None:
            raise UserError("--workers applies to the embedded LocalCluster, not to --scheduler")
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except OSError as exc:
            raise UserError(
                f"--scheduler {scheduler}: cannot connect ({' '.join(str(exc).split())})"
            ) from None
        except (ValueError, TypeError) as exc:  # distributed's parser of the address
            raise UserError(
                f"--scheduler {scheduler!r}: not a scheduler address, such as tcp://host:8786 "
                f"({' '.join(str(exc).split())})"
            ) from None
        with client:
            yield client
        return
    count = default_workers() if workers is None else workers
    if count < 1:
        raise UserError(f"--workers must be >= 1, got {count}")
    try:
        cluster = LocalCluster(
            n_workers=count,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            # no dashboard, and the scheduler's HTTP endpoints on a free port rather than on a busy 8787
            scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"},
            silence_logs=logging.ERROR,
            env=ONE_THREAD_ENV,
        )
    except (RuntimeError, OSError) as exc:  # the workers' own failure stays in their processes
        raise UserError(
            f"cannot start the local Dask cluster ({' '.join(str(exc).split())}): a full disk or a file-size "
            f"limit on {tempfile.gettempdir()}, where its workers write? (or give --scheduler ADDRESS)"
        ) from None
    with cluster, Client(cluster) as client:
        yield client
