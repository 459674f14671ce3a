"""Checks of the numeric options many commands share: one message for a value that is not a finite
number in its range (``nan`` and ``inf`` pass a plain ``< 0`` test and fail deep inside the work)."""

from __future__ import annotations

import math
import os

from trainer.errors import UserError

THREADS_PER_CORE = 4  # more torch threads than this many per core only slow the fit down (or crash it)


MAX_SECONDS = 1e6  # a smoothing or a step longer than 11 days is no chamber run's (1e308 overflowed)


def check_finite(
    option: str, value: float, *, minimum: float = 0.0, inclusive: bool = True, maximum: float = math.inf
) -> float:
    """``value`` of ``option`` when finite, at least (``inclusive``) or above ``minimum`` and at most
    ``maximum``."""
    above = value >= minimum if inclusive else value > minimum
    if not (math.isfinite(value) and above and value <= maximum):
        bound = f"{'>=' if inclusive else '>'} {minimum:g}" + (
            f" and <= {maximum:g}" if maximum < math.inf else ""
        )
        raise UserError(f"{option} must be a finite number {bound}, got {value}")
    return value


def check_threads(threads: int) -> int:
    """``--threads``: at least 1 and at most :data:`THREADS_PER_CORE` per core of this machine."""
    most = THREADS_PER_CORE * (os.cpu_count() or 1)
    if not 1 <= threads <= most:
        raise UserError(
            f"--threads must be 1 .. {most} ({THREADS_PER_CORE} per core of this machine), got {threads}"
        )
    return threads
