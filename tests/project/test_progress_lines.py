"""Long work shows progress in a captured log too (CI, a pipe), as plain lines, and short work stays quiet."""

from __future__ import annotations

import io

import pytest

from trainer import progress
from trainer.progress import progress_bar


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_captured_log_gets_plain_lines(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(progress, "LOG_INTERVAL_S", 0.0)
    log = io.StringIO()
    outer = progress_bar(progress=True, total=2, desc="diagnose", unit="stage", file=log, leave=False)
    for _ in range(2):
        inner = progress_bar(range(3), progress=True, desc="search", unit="round", file=log, leave=False)
        for _ in inner:
            pass
        outer.update()
    outer.close()
    text = log.getvalue()
    lines = text.splitlines()
    assert "\r" not in text and "\x1b" not in text  # no redraws, no cursor moves between nested bars
    assert any(line.startswith("search:") and "3/3" in line for line in lines)
    assert any(line.startswith("diagnose:") and "2/2" in line for line in lines)
    assert all(line.strip() for line in lines)


def test_short_work_in_a_log_prints_nothing() -> None:
    log = io.StringIO()
    for _ in progress_bar(range(50), progress=True, desc="quick", file=log):
        pass
    assert log.getvalue() == ""


def test_no_progress_prints_nothing_even_on_a_terminal() -> None:
    terminal = Terminal()
    for _ in progress_bar(range(5), progress=False, desc="quiet", file=terminal):
        pass
    assert terminal.getvalue() == ""


def test_a_terminal_gets_the_live_bar() -> None:
    terminal = Terminal()
    for _ in progress_bar(range(5), progress=True, desc="live", file=terminal, mininterval=0):
        pass
    assert "\r" in terminal.getvalue() and "live" in terminal.getvalue()
