"""One in-process run of a command-line entry point, its output captured (no interpreter start-up).

``run_cli`` is what the installed ``trainer`` and ``codegen`` scripts call: the exit code and the
one-line refusals a user sees come from it, so the tests read them the same way.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from trainer.errors import run_cli


def run_captured(
    main: Callable[[list[str] | None], int], capsys: pytest.CaptureFixture[str], *args: str
) -> tuple[int, str, str]:
    """``(exit code, stdout, stderr)`` of ``main(args)`` run as the entry point runs it."""
    capsys.readouterr()  # drop what earlier steps of the test printed
    code = run_cli(main, list(args))
    out, err = capsys.readouterr()
    return code, out, err
