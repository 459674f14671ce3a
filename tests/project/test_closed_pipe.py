"""A reader that closes the pipe early (``trainer ... | head``, common in CI logs) ends the command
quietly with 141 (128 + SIGPIPE), as a shell tool does: no traceback, no 'Exception ignored'; the
command still writes its files (a per-channel run printed its first channel's lines, then stopped
before writing the other channels' reports)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LOUD = "from trainer.errors import run_cli; import sys; sys.exit(run_cli(lambda argv: [print('line', k) for k in range({n})] and 0))"
# prints, then writes a file, as a per-channel command prints a channel's lines and then its report
LOUD_THEN_WRITES = (
    "from pathlib import Path; from trainer.errors import run_cli; import sys\n"
    "def main(argv):\n"
    "    for k in range({n}):\n"
    "        print('line', k)\n"
    "    Path('report.md').write_text('done')\n"
    "    print('wrote report.md')\n"
    "    return 0\n"
    "sys.exit(run_cli(main))"
)


@pytest.mark.parametrize("script", [LOUD, LOUD_THEN_WRITES], ids=["prints", "prints-then-writes"])
def test_a_closed_pipe_ends_the_command_quietly(script: str, tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    writer = subprocess.Popen(
        [sys.executable, "-c", script.format(n=200_000)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
        cwd=tmp_path,  # not the checkout: PYTHONPATH says which code runs
    )
    assert writer.stdout is not None and writer.stderr is not None
    first = writer.stdout.readline()
    writer.stdout.close()  # the reader goes away after one line
    err = writer.stderr.read().decode()
    code = writer.wait(timeout=60)
    assert first == b"line 0\n"
    assert "Traceback" not in err and "Exception ignored" not in err and err == ""
    assert code == 141  # 200 000 lines do not fit the pipe: the writer meets the closed end
    if script is LOUD_THEN_WRITES:
        assert (tmp_path / "report.md").read_text() == "done"  # the work went on to the end


def test_python_m_runs_both_commands(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for package in ("trainer", "codegen"):
        done = subprocess.run(
            [sys.executable, "-m", package, "--help"],
            capture_output=True,
            text=True,
            env=env,
            timeout=120,
            cwd=tmp_path,
        )
        assert done.returncode == 0 and f"usage: {package}" in done.stdout, done.stderr
