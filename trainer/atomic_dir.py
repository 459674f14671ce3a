"""Write a directory of outputs as one set: a reader sees the old set or the new set, never a mix.

``trainer fit --channels`` (one model per channel and their index) and ``codegen export`` (header,
source, kernels, manifest, blob) write several files that only make sense together. The new set is
built in a sibling staging folder ``.OUT.<pid>.<random>.part`` (entries of an existing OUT that the
new set does not replace are carried over as hard links), then swapped with OUT in one
``renameat2(RENAME_EXCHANGE)``; where the kernel or file system cannot exchange, OUT is moved aside
to ``.OUT.<pid>.<random>.old`` for the instant of a second rename. A killed run therefore leaves at
most such sibling folders, never a mixed OUT; the next run writing OUT removes the ones whose
process is gone (putting a set moved aside back first if OUT is missing) and says so.

When OUT cannot be renamed (its parent is not writable, or OUT is the working directory or holds
it) the files are replaced one by one inside OUT, as before: all written before the first replace,
but a kill between two replaces can leave a mix there.
"""

from __future__ import annotations

import ctypes
import errno
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Collection, Iterator
from contextlib import contextmanager
from pathlib import Path

from trainer.errors import UserError, current_umask, probe_writable
from trainer.stale_files import process_alive, report_removed

STAGING_SUFFIX = ".part"  # the new set being built (or, after the exchange, the old one being removed)
ASIDE_SUFFIX = ".old"  # an existing set moved aside (no atomic exchange on this file system)
_SIBLING = re.compile(r"^\.(?P<name>.+)\.(?P<pid>[0-9]+)\.[A-Za-z0-9_]+(?P<kind>\.part|\.old)$")
# partial files inside a set: trainer.errors.atomic_output's .NAME.<random>.part.EXT and the staging
# folders .OUT.<random>.part that earlier versions made inside OUT
_PARTIAL = re.compile(r"^\..+\.part(\.[A-Za-z0-9]+)?$")
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def check_output_directory(out: str | os.PathLike[str]) -> Path:
    """Fail early (before long work) when ``out`` cannot become a directory of outputs; returns the
    directory that must be writable (``out`` if it exists, else its parent)."""
    target = Path(out)
    if target.exists() and not target.is_dir():
        raise UserError(f"{target}: exists and is not a directory (the outputs go into a directory)")
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise UserError(f"{target}: parent directory {parent} does not exist")
    base = target if target.is_dir() else parent
    if not os.access(base, os.W_OK | os.X_OK):
        raise UserError(f"{target}: directory {base} is not writable")
    probe_writable(base, target)
    return base


def remove_leftovers(out: str | os.PathLike[str]) -> list[str]:
    """Remove the sibling folders killed runs writing ``out`` left (their process is gone); a set
    moved aside is put back first when ``out`` is missing. Returns the names removed or restored."""
    target = Path(os.path.abspath(out))
    if not target.parent.is_dir():
        return []
    stale = []
    for entry in sorted(target.parent.iterdir()):
        match = _SIBLING.match(entry.name)
        if match is None or match["name"] != target.name or not entry.is_dir() or entry.is_symlink():
            continue
        if not process_alive(int(match["pid"])):
            stale.append(entry)
    found = [entry.name for entry in stale]
    aside = [entry for entry in stale if entry.name.endswith(ASIDE_SUFFIX)]
    if aside and not os.path.lexists(target):  # killed between moving the old set aside and the swap
        os.rename(aside[0], target)
        stale.remove(aside[0])
    for entry in stale:
        shutil.rmtree(entry, ignore_errors=True)
    return found


def _link_or_copy(source: str, destination: str) -> None:
    try:
        os.link(source, destination)
    except OSError:  # hard links not allowed here: a copy is the same content
        shutil.copy2(source, destination)


def _carry_over(target: Path, staging: Path, drop: Collection[str] = ()) -> list[str]:
    """Link the entries of ``target`` the new set does not replace into ``staging``, but those named in
    ``drop``; returns the partial files of killed runs found in ``target`` (left out of the new set)."""
    partial = []
    for entry in sorted(target.iterdir()):
        destination = staging / entry.name
        if os.path.lexists(destination) or entry.name in drop:
            continue
        if _PARTIAL.match(entry.name) or _SIBLING.match(entry.name):
            partial.append(entry.name)
        elif entry.is_symlink():
            os.symlink(os.readlink(entry), destination)
        elif entry.is_dir():
            shutil.copytree(entry, destination, symlinks=True, copy_function=_link_or_copy)
        else:
            _link_or_copy(str(entry), str(destination))
    return partial


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one step (Linux renameat2); False where the system cannot."""
    rename2 = getattr(ctypes.CDLL(None, use_errno=True), "renameat2", None)
    if rename2 is None:
        return False
    rename2.argtypes = (ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint)
    if rename2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(code, os.strerror(code), str(b))


def _sibling(target: Path, suffix: str) -> Path:
    return Path(tempfile.mkdtemp(prefix=f".{target.name}.{os.getpid()}.", suffix=suffix, dir=target.parent))


def _swap_in(staging: Path, target: Path) -> None:
    """Make ``staging`` the set at ``target``; what was at ``target`` ends at ``staging``'s path or is removed."""
    if not target.exists():
        os.rename(staging, target)
        return
    if _exchange(staging, target):
        shutil.rmtree(staging, ignore_errors=True)  # now the old set
        return
    aside = _sibling(target, ASIDE_SUFFIX)
    os.rmdir(aside)  # a fresh unique name for the old set
    os.rename(target, aside)
    try:
        os.rename(staging, target)
    except BaseException:
        os.rename(aside, target)
        raise
    shutil.rmtree(aside, ignore_errors=True)


def _renameable(target: Path) -> bool:
    cwd = Path.cwd()
    inside = cwd == target or target in cwd.parents
    return not inside and os.access(target.parent, os.W_OK | os.X_OK)


@contextmanager
def atomic_directory(out: str | os.PathLike[str], drop: Collection[str] = ()) -> Iterator[Path]:
    """Yield an empty staging folder; when the block succeeds its entries become ``out``'s (other
    entries of an existing ``out`` are kept, but the files named in ``drop``: the previous set's own
    outputs the new set does not hold) as one set, else nothing of it remains.

    A write error (disk full, permissions) is a one-line :class:`UserError` naming ``out``."""
    given = Path(out)
    check_output_directory(given)
    target = Path(os.path.abspath(given))
    in_place = target.is_dir() and not _renameable(target)
    try:
        leftovers = [] if in_place else remove_leftovers(target)
        staging = (
            Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=STAGING_SUFFIX, dir=target))
            if in_place
            else _sibling(target, STAGING_SUFFIX)
        )
    except OSError as exc:
        raise UserError(f"{given}: cannot write ({exc.strerror})") from None
    try:
        yield staging
        if in_place:
            new_set = sorted(staging.iterdir())
            for item in new_set:
                os.replace(item, target / item.name)
            staging.rmdir()
            for name in set(drop) - {item.name for item in new_set}:
                if (target / name).is_file():
                    (target / name).unlink()
        else:
            if target.is_dir():
                leftovers += _carry_over(target, staging, drop)
                os.chmod(staging, stat.S_IMODE(target.stat().st_mode))
            else:
                os.chmod(staging, 0o777 & ~current_umask())
            _swap_in(staging, target)
    except OSError as exc:
        shutil.rmtree(staging, ignore_errors=True)
        raise UserError(f"{given}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    report_removed(given, leftovers)
