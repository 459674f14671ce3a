"""Temporary files of killed runs (``.NAME.<pid>.<random>.part.EXT`` beside an output) are removed
by the next run writing that output; those of a live writer, and lock files, stay."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.repo import REPO_ROOT
from trainer.cli import main as trainer_main
from trainer.errors import run_cli
from trainer.stale_files import remove_stale_parts

ROOT = REPO_ROOT
KILL_WAIT_S = 60.0


def _dead_pid() -> int:
    """The id of a process that has exited (and was reaped)."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def _parts(folder: Path, name: str) -> list[Path]:
    return sorted(folder.glob(f".{name}.*.part*"))


def test_a_killed_simulate_leaves_a_part_file_that_the_next_run_removes(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sim.csv"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code = "import sys; from trainer.cli import entry; sys.argv[0] = 'trainer'; entry()"
    argv = ["simulate", "--seed", "1", "--duration", "3000", "-o", str(out)]  # 600,000 rows: seconds to write
    writer = subprocess.Popen([sys.executable, "-c", code, *argv], env=env, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + KILL_WAIT_S
    while not _parts(tmp_path, out.name) and writer.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    writer.send_signal(signal.SIGKILL)
    writer.wait()
    left = _parts(tmp_path, out.name)
    assert writer.returncode == -signal.SIGKILL and len(left) == 1, "the kill came after the write finished"
    assert f".{writer.pid}." in left[0].name and not out.exists()
    capfd.readouterr()

    assert run_cli(trainer_main, ["simulate", "--seed", "1", "--duration", "60", "-o", str(out)]) == 0
    err = capfd.readouterr().err
    assert _parts(tmp_path, out.name) == [] and out.is_file()
    notes = [line for line in err.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and left[0].name in notes[0], err


def test_only_parts_of_gone_writers_of_that_output_are_removed(tmp_path: Path) -> None:
    dead = _dead_pid()
    with subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"]) as live:
        try:
            files = {
                "stale": f".m.pt.{dead}.abcd_fgh.part.pt",
                "live": f".m.pt.{live.pid}.abcdefgh.part.pt",
                "ours": f".m.pt.{os.getpid()}.abcdefgh.part.pt",
                "other output": f".n.pt.{dead}.abcdefgh.part.pt",
                "lock": ".m.pt.lock",
                "no pid": ".m.pt.abcdefgh.part.pt",
                "user file": "m.pt",
            }
            for name in files.values():
                (tmp_path / name).write_bytes(b"x")
            assert remove_stale_parts(tmp_path, "m.pt") == [files["stale"]]
            kept = {p.name for p in tmp_path.iterdir()}
            assert kept == set(files.values()) - {files["stale"]}
            assert remove_stale_parts(tmp_path) == [files["other output"]]  # any output's
        finally:
            live.kill()


def test_a_fleet_restart_removes_the_report_and_figure_parts(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    dead = _dead_pid()
    out = tmp_path / "out"
    (out / "figures").mkdir(parents=True)
    stale = [
        out / "figures" / f".drift_left.png.{dead}.abcdefgh.part.png",
        out / f".report.md.{dead}.abc_efgh.part.md",
        out / f".fleet.json.{dead}.abcdefgh.part.json",
    ]
    for path in stale:
        path.write_bytes(b"half a file")
    manifest = tmp_path / "fleet.csv"
    manifest.write_text("id,recordings\nU1,missing.csv\n")  # a unit failing at load: no cluster needed
    assert run_cli(trainer_main, ["fleet", str(manifest), "-o", str(out), "--quiet"]) == 1  # U1 FAILs
    assert not any(path.exists() for path in stale)
    assert sorted(p.name for p in out.rglob(".*")) == []
    assert capfd.readouterr().err.count("leftover(s) of an interrupted run") == 2  # out/ and figures/
