"""The memory and time budget every user-chosen size is checked against, before allocation.

A size the user types (``--intervals``, ``--duration``, ``--rate``, a TOML hold of ``1e12`` s, a
DLSTM population, a fleet manifest's fit options) decides how much memory and time a command
takes. A typo must be a one-line error naming the option, not a process the kernel kills after
it grew to 24 GB. Each caller estimates what its size costs (bytes, seconds) with the constants
below and asks :func:`check_memory` / :func:`check_time`; the budget itself is declared here once.
"""

from __future__ import annotations

import math
import os

from trainer.errors import UserError

MEMORY_SHARE = 0.5  # of the memory available when the check runs: the rest is for others
TIME_BUDGET_S = 24 * 3600.0  # one run longer than a day is a typo, not a plan
FLOAT_BYTES = 8
# Peak bytes per value of a recording column while it is simulated and written (a column and
# its formatted copy; measured with tracemalloc on simulate + write_recording: 11..14 B).
RECORDING_BYTES_PER_VALUE = 2 * FLOAT_BYTES
_FALLBACK_MEMORY_BYTES = 1 << 30  # when the platform says nothing: assume 1 GiB


def available_memory_bytes() -> int:
    """Memory available now (Linux ``MemAvailable``; else physical pages; else 1 GiB)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (OSError, ValueError, AttributeError):
        return _FALLBACK_MEMORY_BYTES


def memory_budget_bytes() -> float:
    return MEMORY_SHARE * available_memory_bytes()


def _size_text(nbytes: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes / 1e3:.3g} kB"


def _time_text(seconds: float) -> str:
    if seconds >= 3600:
        return f"{seconds / 3600:.3g} h"
    return f"{seconds:.3g} s"


def check_memory(nbytes: float, what: str, fix: str) -> None:
    """Refuse ``what`` (e.g. ``--intervals 1000000000``) when it needs more than the budget.

    ``nbytes`` may be a float (``inf`` and overflowed products are refused, never converted).
    """
    budget = memory_budget_bytes()
    if not nbytes <= budget:  # also NaN
        need = f"about {_size_text(nbytes)}" if math.isfinite(nbytes) else "unbounded memory"
        raise UserError(
            f"{what}: needs {need}, above the memory budget of {_size_text(budget)} "
            f"({MEMORY_SHARE:.0%} of the {_size_text(available_memory_bytes())} available now); {fix}"
        )


def check_time(seconds: float, what: str, fix: str) -> None:
    """Refuse ``what`` when its estimated run time is above :data:`TIME_BUDGET_S`."""
    if not seconds <= TIME_BUDGET_S:
        need = f"about {_time_text(seconds)}" if math.isfinite(seconds) else "unbounded time"
        raise UserError(f"{what}: would run {need}, above the {_time_text(TIME_BUDGET_S)} budget; {fix}")


def check_rows(rows: float, columns: int, what: str, fix: str) -> int:
    """A recording of ``rows`` x ``columns`` fits the memory budget; the row count as an int."""
    check_memory(rows * columns * RECORDING_BYTES_PER_VALUE, f"{what} ({rows:.4g} rows)", fix)
    return round(rows)
