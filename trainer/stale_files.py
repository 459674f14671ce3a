"""Leftovers of killed runs: which temporary files and folders beside an output are stale.

A temporary output (:func:`trainer.errors.atomic_output`'s ``.NAME.<pid>.<random>.part.EXT``, the
staging folders of :mod:`trainer.atomic_dir`) carries its writer's process id, so that the next run
writing the same output can tell a kill's leftover (process gone) from a run still writing (process
alive) and remove only the former. Lock files (``.NAME.lock``, :mod:`trainer.output_lock`) never
match.
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

# .NAME.<pid>.<8 random characters of tempfile>.part[.EXT]
_PART_FILE = re.compile(r"^\.(?P<name>.+)\.(?P<pid>[0-9]+)\.[A-Za-z0-9_]{8}\.part(?:\.[A-Za-z0-9_]+)?$")


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` may still be writing (ours, another user's, or unknown: alive)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    except OverflowError:
        return False
    return True


def part_prefix(target: Path) -> str:
    """The name prefix of this process's temporary files for output ``target``."""
    return f".{target.name}.{os.getpid()}."


def remove_stale_parts(directory: str | os.PathLike[str], name: str | None = None) -> list[str]:
    """Remove the temporary files of killed writers in ``directory`` (of output ``name`` only, or of
    any output); returns the names removed. Files of live processes and anything else stay."""
    folder = Path(directory)
    if not folder.is_dir():
        return []
    removed = []
    for entry in sorted(folder.iterdir()):
        match = _PART_FILE.match(entry.name)
        if match is None or (name is not None and match["name"] != name):
            continue
        if entry.is_symlink() or not entry.is_file() or process_alive(int(match["pid"])):
            continue
        try:
            entry.unlink()
        except FileNotFoundError:  # another run removed it first
            continue
        except OSError:  # not ours to remove (permissions): left, and not reported as removed
            continue
        removed.append(entry.name)
    return removed


def report_removed(where: str | os.PathLike[str], names: list[str]) -> None:
    """One ``note:`` line on stderr naming what was removed (nothing when ``names`` is empty)."""
    if names:
        print(
            f"note: {where}: removed {len(names)} leftover(s) of an interrupted run: {', '.join(names)}",
            file=sys.stderr,
        )
