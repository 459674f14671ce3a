"""Two runs on one output: the second fails at once, naming the output and the other process."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from codegen.cli import main as codegen_main
from trainer.cli import main as trainer_main
from trainer.errors import run_cli
from trainer.output_lock import lock_path, output_lock

HOLD = "import sys, time\nfrom trainer.output_lock import output_lock\nwith output_lock(sys.argv[1]):\n    print('locked', flush=True)\n    time.sleep(120)\n"


@pytest.fixture
def holder(tmp_path: Path) -> Iterator[tuple[Path, subprocess.Popen[str]]]:
    """Another process holding the lock of ``tmp_path/out``."""
    out = tmp_path / "out"
    process = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE, text=True)
    assert process.stdout is not None and process.stdout.readline() == "locked\n"
    yield out, process
    process.kill()
    process.wait(timeout=30)


COMMANDS: dict[str, tuple[Callable[[list[str] | None], int], list[str]]] = {
    "fit": (trainer_main, ["fit", "--method", "poly3", "rec.npz", "-o"]),
    "fleet": (trainer_main, ["fleet", "fleet.toml", "-o"]),
    "export": (codegen_main, ["export", "model.pt", "-o"]),
}


@pytest.mark.parametrize("command", COMMANDS)
def test_second_writer_is_refused(
    command: str, holder: tuple[Path, subprocess.Popen[str]], capsys: pytest.CaptureFixture[str]
) -> None:
    out, process = holder
    main, argv = COMMANDS[command]
    assert run_cli(main, [*argv, str(out)]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"error: {out}: another run (process {process.pid}) is writing this output now; wait for it to finish "
        f"or choose another output\n"
    )
    assert not out.exists()


def test_a_killed_holder_blocks_nobody(holder: tuple[Path, subprocess.Popen[str]]) -> None:
    out, process = holder
    assert lock_path(out).read_text() == f"{process.pid}\n"
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=30)
    assert lock_path(out).exists()  # left by the killed run, but no longer held
    with output_lock(out):
        assert lock_path(out).read_text() == f"{os.getpid()}\n"
    assert not lock_path(out).exists()  # removed when the run ends
