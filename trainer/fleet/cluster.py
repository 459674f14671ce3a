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
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from functools import wraps
from typing import Any, ParamSpec, TypeVar

from threadpoolctl import threadpool_limits

from trainer.errors import UserError
from trainer.heap import keep_freed_memory

P = ParamSpec("P")
R = TypeVar("R")
T = TypeVar("T")
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
    """Run ``function`` inside :func:`one_thread`, its process keeping freed heap memory as the
    ``trainer`` command does (:mod:`trainer.heap`). Every task sent to a worker is wrapped: Dask
    starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536``, which handed the finder's large
    temporaries back to the kernel at each free, and a physics fit ran 1.7 times slower on a worker
    than in the command (gyro z of the bundled run: 20.1 s against 11.9 s; 12.8 s keeping them)."""

    @wraps(function)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        keep_freed_memory()  # mallopt: cheap, and only where memory comes from changes
        with one_thread():
            return function(*args, **kwargs)

    return wrapper


# the resource tracker's warning when it frees, at exit, what a killed worker left (a semaphore)
TRACKER_WARNING = "ignore::UserWarning:multiprocessing.resource_tracker"


def quiet_resource_tracker() -> None:
    """Start multiprocessing's resource tracker without its exit warning about leaked semaphores.

    A worker killed mid-task (the OOM killer, Ctrl-C) leaves a semaphore that the tracker frees when
    the command exits, and its two-line ``UserWarning`` followed the command's one-line refusal. The
    tracker is its own process and reads its warning filters from the environment it starts with;
    what it frees is unchanged. Does nothing if the tracker is already running."""
    from multiprocessing import resource_tracker

    previous = os.environ.get("PYTHONWARNINGS")
    os.environ["PYTHONWARNINGS"] = ",".join(filter(None, [previous, TRACKER_WARNING]))
    try:
        resource_tracker.ensure_running()
    finally:
        if previous is None:
            del os.environ["PYTHONWARNINGS"]
        else:
            os.environ["PYTHONWARNINGS"] = previous


def default_workers() -> int:
    return max(1, os.cpu_count() or 1)


@contextmanager
def open_client(
    scheduler: str | None, workers: int | None, instead: str = "give --scheduler ADDRESS"
) -> Iterator[Any]:
    """A ``distributed.Client`` on ``scheduler`` (an address), else on a new ``LocalCluster``.

    ``workers`` is the LocalCluster's number of single-threaded worker processes (default: the
    machine's cores); with ``scheduler`` the cluster's own workers are used and ``workers`` must
    not be given. ``instead``: what the user can do when the LocalCluster cannot start.
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
    quiet_resource_tracker()
    try:
        cluster = LocalCluster(
            n_workers=count,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            # no dashboard, and the scheduler's HTTP endpoints on a free port rather than on a busy 8787
            scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"},
            # the scheduler's own ERROR lines (a worker that died) would surround the one-line refusal
            silence_logs=logging.CRITICAL,
            env=ONE_THREAD_ENV,
        )
    except (RuntimeError, OSError) as exc:  # the workers' own failure stays in their processes
        raise UserError(
            f"cannot start the local Dask cluster ({' '.join(str(exc).split())}): a full disk or a file-size "
            f"limit on {tempfile.gettempdir()}, where its workers write? (or {instead})"
        ) from None
    with cluster, Client(cluster) as client:
        yield client


class TaskMap:
    """Maps a function over tasks in this process (one worker) or on Dask workers, each task pinned
    to one thread (:func:`one_thread`) either way, so that a result does not depend on where it ran;
    results come back in task order. The cluster starts at the first map that runs in parallel (a
    command whose fits are all quick never starts one) and stops with :func:`task_map`'s block."""

    def __init__(
        self,
        workers: int = 1,
        scheduler: str | None = None,
        stack: ExitStack | None = None,
        option: str = "--workers",
    ) -> None:
        if scheduler is None and workers < 1:
            raise UserError(f"{option} must be >= 1, got {workers}")
        self.workers = workers
        self.scheduler = scheduler
        self.option = option  # the command's option that sets ``workers`` (said in its refusals)
        self._stack = stack
        self._client: Any = None

    @property
    def parallel(self) -> bool:
        return self.scheduler is not None or self.workers > 1

    @property
    def client(self) -> Any:
        """The Dask client (None in this process), started on first use."""
        if not self.parallel:
            return None
        if self._client is None:
            if self._stack is None:
                raise RuntimeError("TaskMap: open it with task_map() to run on a cluster")
            self._client = self._stack.enter_context(
                open_client(
                    self.scheduler,
                    None if self.scheduler is not None else self.workers,
                    instead=f"give {self.option} 1 to run in this process",
                )
            )
        return self._client

    @property
    def width(self) -> int:
        """How many tasks run at once."""
        if not self.parallel:
            return 1
        return max(1, len(self.client.scheduler_info().get("workers", {})) or self.workers)

    def map(
        self,
        function: Callable[..., R],
        tasks: Sequence[T],
        *,
        shared: dict[str, Any] | None = None,
        here: bool = False,
        done: Callable[[int, T, R], None] | None = None,
    ) -> list[R]:
        """``[function(task, **shared) for task in tasks]``; ``shared`` is sent to each worker once;
        ``here`` keeps the tasks in this process (quick ones, where starting workers costs more);
        ``done(count, task, result)`` after each task completes, in the order they complete."""
        shared = shared or {}
        run = pinned(function)  # the same here as on a worker
        if here or not self.parallel or len(tasks) < 2:
            results = []
            for count, task in enumerate(tasks, start=1):
                results.append(run(task, **shared))
                if done is not None:
                    done(count, task, results[-1])
            return results
        from concurrent.futures import CancelledError

        from distributed import KilledWorker, as_completed

        client = self.client
        sent = {name: client.scatter(value, broadcast=True) for name, value in shared.items()}
        futures = client.map(run, list(tasks), pure=False, **sent)
        which = {future.key: task for future, task in zip(futures, tasks, strict=True)}
        try:
            for count, future in enumerate(as_completed(futures), start=1):
                # a task's own exception is raised here at once (the block's exit stops the rest)
                result = future.result()
                if done is not None:
                    done(count, which[future.key], result)
        except (KilledWorker, CancelledError):  # cancelled: every worker holding the shared data died
            each = f"each of the {self.workers} workers" if self.scheduler is None else "each worker"
            raise UserError(
                f"a worker process died while running a task (out of memory? {each} holds its own copy of "
                f"the data): give {self.option} 1 to run in this process"
            ) from None
        return [future.result() for future in futures]


@contextmanager
def task_map(workers: int = 1, scheduler: str | None = None, option: str = "--workers") -> Iterator[TaskMap]:
    """A :class:`TaskMap` whose cluster (if it starts one) stops at the end of the block; ``option``
    is the command's name for ``workers``."""
    with ExitStack() as stack:
        tasks = TaskMap(workers, scheduler, stack, option)
        if scheduler is not None:  # the cluster the user named is checked before any work, even work that
            tasks.client  # noqa: B018 - stays here (a bad address was ignored when every task was quick)
        yield tasks
