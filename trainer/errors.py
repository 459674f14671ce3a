"""User-facing errors: one line, no traceback, non-zero exit.

Every problem caused by the user's input (a recording, a config, a model file, a CLI argument)
is raised as :class:`UserError`. The CLI entry points catch it, print ``error: <message>`` on
stderr and exit with status 2. Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

EXIT_USER_ERROR = 2
_TERMINAL_CODES = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|[\x00-\x08\x0b-\x1f\x7f]")  # colours, cursor moves


class UserError(Exception):
    """Bad input from the user; the message must name the file, row, column or field."""


class OneLineArgumentParser(argparse.ArgumentParser):
    """argparse that reports usage errors as a one-line UserError instead of exiting itself."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UserError(f"{self.prog}: {message}")


def run_cli(main: Callable[[list[str] | None], int], argv: list[str] | None = None) -> int:
    """Run a CLI ``main`` and turn :class:`UserError` into a one-line message and exit code 2."""
    try:
        return main(argv)
    except UserError as exc:
        message = " ".join(_TERMINAL_CODES.sub("", str(exc)).split())  # one line, no terminal codes
        print(f"error: {message}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


def check_output_path(path: str | os.PathLike[str]) -> None:
    """Fail early (before long work) when ``path`` cannot be written; creates nothing."""
    target = Path(path)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise UserError(f"{target}: output directory {parent} does not exist")
    if not os.access(parent, os.W_OK) or (target.exists() and not os.access(target, os.W_OK)):
        raise UserError(f"{target}: not writable")


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_output(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only on success.

    Guarantees that a failed command leaves no partial output file behind.
    """
    target = Path(path)
    check_output_path(target)
    parent = target.parent if str(target.parent) else Path(".")
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part" + target.suffix, dir=parent)
    os.close(fd)
    tmp = Path(tmp_name)
    os.chmod(tmp, 0o666 & ~_current_umask())  # mkstemp creates 0600; outputs get the usual mode
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
