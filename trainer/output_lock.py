"""One writer per output: an advisory lock beside each output for the whole run of a command.

Two ``fit``, ``export`` or ``fleet`` runs on one output would both report success and the last
one would silently win. Both CLIs (``trainer``, ``codegen``) take, before the command runs, an
``fcntl.flock`` on ``.<output name>.lock`` beside each output the command names (``-o``,
``--out-dir``); a second run fails at once with one line naming the output and the process
holding it. The lock dies with its process (a killed run never blocks the next one), and the
lock file is removed when the run ends.
"""

from __future__ import annotations

import argparse
import fcntl
import os
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager, suppress
from pathlib import Path

from trainer.errors import UserError

OUTPUT_OPTIONS = ("output", "out_dir")  # the argparse destinations that name a command's outputs


def lock_path(output: str | os.PathLike[str]) -> Path:
    target = Path(output)
    return target.parent / f".{target.name}.lock"


def _open_locked(lock: Path, target: Path) -> int | None:
    """A descriptor holding the lock on ``lock`` (the file as it is on disk now), or None when
    no lock file can be made there (the command reports the unwritable place itself)."""
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:
            return None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode("ascii", errors="replace").strip() or "unknown"
            os.close(fd)
            raise UserError(
                f"{target}: another run (process {holder}) is writing this output now; wait for it to finish "
                f"or choose another output"
            ) from None
        try:
            current = os.stat(lock).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            current = False
        if current:  # else the previous holder removed the file between our open and flock: again
            return fd
        os.close(fd)


@contextmanager
def output_lock(output: str | os.PathLike[str]) -> Iterator[None]:
    """Hold the lock of ``output`` for the body; fails at once when another process holds it."""
    target = Path(output)
    lock = lock_path(target)
    if not lock.parent.is_dir():
        yield  # the command refuses the missing folder itself
        return
    fd = _open_locked(lock, target)
    if fd is None:
        yield
        return
    try:
        with suppress(OSError):  # a full disk: the lock holds without the process id
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode("ascii"))
        yield
    finally:
        lock.unlink(missing_ok=True)
        os.close(fd)


@contextmanager
def command_outputs_locked(args: argparse.Namespace) -> Iterator[None]:
    """The locks of every output a parsed command line names (see :data:`OUTPUT_OPTIONS`)."""
    outputs = [getattr(args, name) for name in OUTPUT_OPTIONS if isinstance(getattr(args, name, None), str)]
    with ExitStack() as stack:
        for output in dict.fromkeys(outputs):
            stack.enter_context(output_lock(output))
        yield
