"""Run the finder's many small dense factorisations on one BLAS thread.

The search factorises a ~900 x 900 covariance hundreds of times. OpenBLAS splits each call over
all cores and its threads spin while waiting; on the project's shared 2-core machine that made a
diagnosis 5-10 times slower than one thread (measured: 36-86 s against 7 s). threadpoolctl
limits every loaded BLAS library for the duration of the block and restores the previous limits.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from threadpoolctl import threadpool_limits


@contextmanager
def single_blas_thread() -> Iterator[None]:
    """Limit every loaded BLAS library to one thread inside the block, then restore."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield
