"""User-facing errors: one line, no traceback, non-zero exit.

Every problem caused by the user's input (a recording, a config, a model file, a CLI argument)
is raised as :class:`UserError`. The CLI entry points catch it, print ``error: <message>`` on
stderr and exit with status 2. Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import errno
import os
import re
import signal
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack, contextmanager, suppress
from pathlib import Path
from typing import Any, TextIO

from trainer.log_kinds import A_KIND, existing_log_kind
from trainer.stale_files import part_prefix, remove_stale_parts, report_removed

EXIT_USER_ERROR = 2
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE: what a shell tool exits with when its reader closes the pipe
# Write failures the user can fix (disk full, file-size or quota limit, permissions, read-only
# file system): one line naming the path, never a traceback.
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EACCES, errno.EPERM, errno.EROFS})
# A temporary file or staging folder beside an output (an optional writer's process id and tempfile's
# 8 random characters between the output's name and an optional ``.part``/``.old`` suffix): messages
# name the output instead.
_STAGED_NAMES = (
    re.compile(r"\.(?P<name>.+)\.[0-9]+\.[A-Za-z0-9_]{8}(?:\.part.*|\.old)"),  # with the writer's pid
    re.compile(r"\.(?P<name>.+)\.[A-Za-z0-9_]{8}(?:\.part.*|\.old)?"),
)
_TERMINAL_CODES = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|[\x00-\x08\x0b-\x1f\x7f]")  # colours, cursor moves


class UserError(Exception):
    """Bad input from the user; the message must name the file, row, column or field."""


# the hint of a file of the wrong kind in an argument's place (a recording where a TOML goes, ...)
SWAPPED_HINT = "arguments swapped? see the command's --help for which comes where"


class OneLineArgumentParser(argparse.ArgumentParser):
    """argparse that reports usage errors as a one-line UserError instead of exiting itself, and
    reads no prefix of an option as the option (``codegen verify --channel`` was read as
    ``--channels``, an option it has, and failed on what followed)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UserError(f"{self.prog}: {message}")


def _output_part(part: str) -> str:
    for pattern in _STAGED_NAMES:
        if match := pattern.fullmatch(part):
            return match["name"]
    return part


def output_name(path: str | os.PathLike[str] | None) -> str | None:
    """``path`` as the user knows it: staging folders and ``.part`` files replaced by their outputs."""
    if path is None:
        return None
    parts = [_output_part(part) for part in Path(path).parts]
    return str(Path(*parts)) if parts else str(path)


def write_error(exc: OSError, path: str | os.PathLike[str] | None = None) -> UserError | None:
    """The one-line UserError for a write failure of :data:`WRITE_ERRNOS` (None for other errors)."""
    if exc.errno not in WRITE_ERRNOS:
        return None
    where = output_name(path if path is not None else exc.filename)
    reason = os.strerror(exc.errno)
    if where is None:
        return UserError(f"cannot write an output ({reason}): free space or raise the limit, then run again")
    return UserError(f"{where}: cannot write ({reason}); nothing was written there")


def raise_write_error(exc: BaseException, path: str | os.PathLike[str]) -> None:
    """Raise the one-line UserError naming output ``path`` if ``exc`` is a failed write of a
    staging folder for ``path`` (a write through an open file names no path); else return."""
    if isinstance(exc, OSError):
        converted = write_error(exc, path if exc.filename is None else None)
        if converted is not None:
            raise converted from None


def _ignore_file_size_signal() -> None:
    """A file-size limit (RLIMIT_FSIZE) sends SIGXFSZ, which kills the process without a word;
    ignored, the write fails with EFBIG instead and is reported like a full disk."""
    xfsz = getattr(signal, "SIGXFSZ", None)
    if xfsz is not None:
        with suppress(ValueError):  # not the main thread: leave the process's handlers alone
            signal.signal(xfsz, signal.SIG_IGN)


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so that the interpreter's last flush does not raise again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    with suppress(OSError, ValueError):
        os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


class _OutlivesReader:
    """stdout that outlives its reader: once the pipe is closed (``trainer ... | head``) what is still
    printed goes nowhere and the command goes on to write its files (a per-channel run's later
    channels, its report); :func:`run_cli` then exits 141. Everything else is the stream's own."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.reader_gone = False

    def write(self, text: str) -> int:
        if not self.reader_gone:
            try:
                return self.stream.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self) -> None:
        if not self.reader_gone:
            try:
                self.stream.flush()
            except BrokenPipeError:
                self._gone()

    def _gone(self) -> None:
        self.reader_gone = True
        _silence_stdout()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stream, name)


def _print_error(exc: UserError) -> int:
    message = " ".join(_TERMINAL_CODES.sub("", str(exc)).split())  # one line, no terminal codes
    print(f"error: {message}", file=sys.stderr)
    return EXIT_USER_ERROR


def run_cli(main: Callable[[list[str] | None], int], argv: list[str] | None = None) -> int:
    """Run a CLI ``main`` and turn :class:`UserError` (and a failed write) into a one-line message
    and exit code 2."""
    _ignore_file_size_signal()
    guard = _OutlivesReader(sys.stdout)
    sys.stdout = guard
    try:
        code = main(argv)
        guard.flush()  # a closed pipe shows here, not in the interpreter's exit
        # the reader went away (``| head``): the work is done, the exit status says the pipe closed
        return EXIT_BROKEN_PIPE if guard.reader_gone and code == 0 else code
    except UserError as exc:
        return _print_error(exc)
    except BrokenPipeError:  # a closed pipe met outside stdout's writes: stop quietly, as a shell tool does
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except OSError as exc:
        converted = write_error(exc)
        if converted is None:
            raise
        return _print_error(converted)
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    finally:
        if sys.stdout is guard:
            sys.stdout = guard.stream


def check_output_path(path: str | os.PathLike[str], *, inputs: Sequence[str | os.PathLike[str]] = ()) -> None:
    """Fail early (before long work) when ``path`` cannot be written, is a directory, is one of
    the command's ``inputs`` or is a flight log (writing it would destroy what it is made from, or a
    log: ``diagnose --json log.ulg`` replaced one); creates nothing."""
    target = Path(path)
    if target.is_dir():
        raise UserError(f"{target}: a directory, not a file name for the output")
    if target.is_file() and (kind := existing_log_kind(target)) is not None:
        raise UserError(
            f"{target}: {A_KIND[kind]} flight log: the output written there would destroy it ({SWAPPED_HINT})"
        )
    for source in inputs:
        if _same_path(target, Path(source)):
            raise UserError(
                f"{target}: is also the input {source}; writing it would destroy the input (arguments swapped? "
                "give another output name)"
            )
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise UserError(f"{target}: output directory {parent} does not exist")
    if not os.access(parent, os.W_OK) or (target.exists() and not os.access(target, os.W_OK)):
        raise UserError(f"{target}: not writable")
    probe_writable(parent, target)


def probe_writable(directory: Path, target: str | os.PathLike[str]) -> None:
    """Refuse ``target`` when a file cannot be made in ``directory``: its permissions can say yes where
    the file system says no (/proc, a read-only mount, root's access). The probe is an unnamed
    temporary file, gone when closed: nothing is left."""
    import tempfile

    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as exc:
        raise UserError(f"{target}: cannot write in {directory} ({exc.strerror or exc})") from None


def _same_path(a: Path, b: Path) -> bool:
    """The same file, by its resolved path, or by device and inode when both exist (a hard link)."""
    try:
        if a.exists() and b.exists():
            return a.samefile(b)
        return a.resolve() == b.resolve()
    except OSError:
        return a == b


def current_umask() -> int:
    """The process's umask (reading it means setting it: set back at once)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_output(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only on success.

    Guarantees that a failed command leaves no partial output file behind; the temporary files a
    killed writer of ``path`` left (its process gone) are removed first, in one ``note:`` line.
    A write failure of :data:`WRITE_ERRNOS` on the output becomes a one-line UserError naming
    ``path`` (an error of another file, say an input read in the body, passes unchanged).
    """
    target = Path(path)
    check_output_path(target)
    parent = target.parent if str(target.parent) else Path(".")
    report_removed(target, remove_stale_parts(parent, target.name))
    try:
        fd, tmp_name = tempfile.mkstemp(
            prefix=part_prefix(target), suffix=".part" + target.suffix, dir=parent
        )
    except OSError as exc:
        raise write_error(exc, target) or exc from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        os.chmod(tmp, 0o666 & ~current_umask())  # mkstemp creates 0600; outputs get the usual mode
        yield tmp
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        ours = exc.filename is None or Path(exc.filename) in (tmp, target)
        converted = write_error(exc, target) if ours else None
        if converted is None:
            raise
        raise converted from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextmanager
def atomic_outputs(paths: Sequence[str | os.PathLike[str]]) -> Iterator[list[Path]]:
    """:func:`atomic_output` for a set of files (a report and its figures): one temporary path per
    output; all are renamed onto their outputs only when the body succeeded, so a failure leaves
    none of them new."""
    with ExitStack() as stack:
        yield [stack.enter_context(atomic_output(path)) for path in paths]
