"""Keep freed heap memory in the process instead of handing it back to the kernel (glibc).

Why: one DLSTM training iteration allocates and frees oneDNN workspaces of several to tens of MB
(gates and states over the whole sequence), and the scoring makes many temporaries of a
recording's length. With glibc's defaults such blocks are mmap-ed and unmapped, or trimmed off the
heap top, so every reuse costs the kernel one page fault per 4 KiB page plus zeroing it: on the
realistic experiment about 10,000 faults per training iteration of a 3-network group, most of the
main job's 46 million page faults and 140 s of system time. Serving every block from the heap and
keeping up to :data:`TRIM_THRESHOLD_BYTES` of freed memory makes the next allocation reuse the
same, already-mapped pages (the cost: a process's memory is given back to the system only at exit
or beyond that threshold).

Only where memory comes from changes, never what is computed: torch aligns every buffer to 64 bytes
whichever way the allocator serves it, and ``tests/methods/test_heap.py`` checks that a population
trains to the same bits with and without this setting.
"""

from __future__ import annotations

import ctypes
import sys

# mallopt(3) parameters (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_TOP_PAD = -2
M_MMAP_MAX = -4
# No block gets its own mapping, whatever its size: glibc's largest mmap threshold (32 MiB) is below
# the workspaces of a realistic-experiment group (18,400 steps), which would fault afresh each time.
MMAP_MAX_BLOCKS = 0
# Freed memory at the heap top kept for reuse; beyond it glibc trims as usual.
TRIM_THRESHOLD_BYTES = 1024 * 1024 * 1024
# Each heap extension asks the kernel for this much more, so growth is rare.
TOP_PAD_BYTES = 64 * 1024 * 1024


def keep_freed_memory() -> bool:
    """Set glibc's malloc to keep freed memory (see the module docstring); False where it cannot
    (not Linux, or a C library without ``mallopt``): nothing changes there."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    settings = (
        (M_MMAP_MAX, MMAP_MAX_BLOCKS),
        (M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES),
        (M_TOP_PAD, TOP_PAD_BYTES),
    )
    return all(mallopt(parameter, value) == 1 for parameter, value in settings)
