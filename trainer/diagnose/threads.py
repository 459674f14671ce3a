"""Run the finder's many small dense factorisations on one BLAS thread.

The search factorises a ~900 x 900 covariance hundreds of times. OpenBLAS splits each call over
all cores and its threads spin while waiting; on the project's shared 2-core machine that made a
diagnosis 5-10 times slower than one thread (measured: 36-86 s against 7 s). threadpoolctl is not
a dependency, so the OpenBLAS libraries already loaded are found in ``/proc/self/maps`` and their
``set_num_threads`` entry points called through ctypes; anywhere that fails this is a no-op.
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterator
from contextlib import contextmanager

_SETTERS = (
    "scipy_openblas_set_num_threads64_",
    "scipy_openblas_set_num_threads",
    "openblas_set_num_threads64_",
    "openblas_set_num_threads",
)
_GETTERS = (
    "scipy_openblas_get_num_threads64_",
    "scipy_openblas_get_num_threads",
    "openblas_get_num_threads64_",
    "openblas_get_num_threads",
)


def _openblas_handles() -> list[tuple[ctypes._CFuncPtr, ctypes._CFuncPtr]]:  # type: ignore[name-defined]
    try:
        with open("/proc/self/maps", encoding="utf-8") as maps:
            paths = {line.split()[-1] for line in maps if "openblas" in line.lower() and "/" in line}
    except OSError:
        return []
    handles = []
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        setter = next((getattr(lib, name) for name in _SETTERS if hasattr(lib, name)), None)
        getter = next((getattr(lib, name) for name in _GETTERS if hasattr(lib, name)), None)
        if setter is not None and getter is not None:
            getter.restype = ctypes.c_int
            handles.append((setter, getter))
    return handles


@contextmanager
def single_blas_thread() -> Iterator[None]:
    """Limit every loaded OpenBLAS to one thread inside the block, then restore."""
    handles = _openblas_handles()
    previous = []
    for setter, getter in handles:
        previous.append(int(getter()))
        setter(1)
    try:
        yield
    finally:
        for (setter, _), count in zip(handles, previous, strict=True):
            setter(count)
