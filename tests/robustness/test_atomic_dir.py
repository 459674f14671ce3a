"""Several outputs written as one set (trainer/atomic_dir.py): old set or new set, never a mix.

Kills are simulated two ways: an exception in the middle of writing (the in-process path), and a
real SIGKILL of a ``codegen export`` child process between two files of the set; the next run must
remove what the killed one left and say so.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from codegen.cli import main as codegen_main
from codegen.export import write_files_atomically
from tests.data_io.test_channels import imu_recording
from tests.repo import REPO_ROOT
from trainer import atomic_dir
from trainer.atomic_dir import atomic_directory, remove_leftovers
from trainer.cli import main as trainer_main
from trainer.data.recording_io import write_recording
from trainer.errors import UserError
from trainer.output_lock import lock_path

ROOT = REPO_ROOT


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def _siblings(target: Path) -> list[str]:
    """Hidden staging entries beside ``target``; the writer's lock file (kept after a kill by
    design, trainer/output_lock.py) is not one."""
    lock = lock_path(target).name
    return sorted(
        p.name for p in target.parent.iterdir() if p.name.startswith(f".{target.name}.") and p.name != lock
    )


def _contents(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir()) if p.is_file()}


@pytest.fixture(scope="module")
def models(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two poly3 fits of the same channels on different runs: two distinguishable sets."""
    root = tmp_path_factory.mktemp("atomic")
    for seed in (3, 4):
        write_recording(imu_recording(n=400, seed=seed), root / f"rec{seed}.npz")
        argv = ["fit", "--method", "poly3", str(root / f"rec{seed}.npz"), "--channels", "accel0_x,accel0_y"]
        assert trainer_main([*argv, "-o", str(root / f"fit{seed}")]) == 0
    return {"root": root, "a": root / "fit3", "b": root / "fit4", "rec": root / "rec4.npz"}


def test_a_new_set_replaces_the_old_one_and_keeps_other_entries(tmp_path: Path) -> None:
    out = tmp_path / "out"
    write_files_atomically({"m.h": "old h", "m.c": "old c"}, out)
    (out / "notes.txt").write_text("mine")
    (out / "sub").mkdir()
    (out / "sub" / "f").write_text("kept")
    inode = out.stat().st_ino
    write_files_atomically({"m.h": "new h", "m.c": "new c"}, out)
    assert (out / "m.h").read_text() == "new h" and (out / "m.c").read_text() == "new c"
    assert (out / "notes.txt").read_text() == "mine" and (out / "sub" / "f").read_text() == "kept"
    assert out.stat().st_ino != inode  # swapped as a whole, not rewritten file by file
    assert _siblings(out) == []


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "two-renames"])
def test_a_failure_in_the_middle_leaves_the_old_set_and_no_staging(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exchange: bool
) -> None:
    if not exchange:
        monkeypatch.setattr(atomic_dir, "_exchange", lambda a, b: False)
    out = tmp_path / "out"
    write_files_atomically({"m.h": "old h", "m.c": "old c"}, out)
    before = _contents(out)
    with pytest.raises(RuntimeError), atomic_directory(out) as staging:
        (staging / "m.h").write_text("new h")
        raise RuntimeError("killed between two files")
    assert _contents(out) == before and _siblings(out) == []
    write_files_atomically({"m.h": "new h", "m.c": "new c"}, out)  # the fallback swap also works
    assert (out / "m.c").read_text() == "new c" and _siblings(out) == []


def test_a_write_error_is_one_line_naming_the_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out"
    write_files_atomically({"m.h": "old"}, out)

    def full(*_: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic_dir, "_swap_in", full)
    with pytest.raises(UserError, match=r"out: cannot write \(No space left on device\)"):
        write_files_atomically({"m.h": "new"}, out)
    assert (out / "m.h").read_text() == "old" and _siblings(out) == []


def test_stale_staging_is_removed_and_a_set_moved_aside_is_put_back(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    dead = _dead_pid()
    staging = tmp_path / f".out.{dead}.abc123.part"
    staging.mkdir()
    (staging / "m.h").write_text("half")
    aside = tmp_path / f".out.{dead}.def456.old"
    aside.mkdir()
    (aside / "m.h").write_text("old set")
    alive = tmp_path / f".out.{os.getppid()}.ghi789.part"  # a live writer's folder is not touched
    alive.mkdir()
    assert remove_leftovers(out) == sorted([aside.name, staging.name])
    assert (out / "m.h").read_text() == "old set"  # killed between moving aside and the swap
    assert _siblings(out) == [alive.name]
    # legacy partial files inside the set (earlier staging, atomic_output temporaries) are dropped
    (out / ".out.x1y2z3.part").mkdir()
    (out / ".m.c.k9k9k9.part.c").write_text("partial")
    write_files_atomically({"m.c": "new"}, out)
    assert sorted(p.name for p in out.iterdir()) == ["m.c", "m.h"]
    assert "removed 2 leftover(s) of an interrupted run" in capsys.readouterr().err


def test_an_interrupted_fit_of_several_channels_leaves_the_old_set(
    models: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import trainer.checkpoint

    out = tmp_path / "set"
    assert (
        trainer_main(
            ["fit", "--method", "poly3", str(models["rec"]), "--channels", "accel0_x", "-o", str(out)]
        )
        == 0
    )
    before = _contents(out)
    real, calls = trainer.checkpoint.save_model, []

    def save_then_die(*args: object, **kwargs: object) -> None:
        calls.append(args)
        if len(calls) == 2:
            raise KeyboardInterrupt  # Ctrl-C after the first channel's file
        real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(trainer.checkpoint, "save_model", save_then_die)
    argv = ["fit", "--method", "pla", str(models["rec"]), "--channels", "accel0_x,accel0_y", "-o", str(out)]
    with pytest.raises(KeyboardInterrupt):
        trainer_main(argv)
    assert len(calls) == 2 and _contents(out) == before and _siblings(out) == []


KILLER = textwrap.dedent(
    """
    import os, signal, sys
    from pathlib import Path
    real = Path.write_text
    count = [0]
    def write_then_die(self, *args, **kwargs):
        count[0] += 1
        if count[0] == 2:
            os.kill(os.getpid(), signal.SIGKILL)  # between two files of the set
        return real(self, *args, **kwargs)
    Path.write_text = write_then_die
    from codegen.cli import main
    main(sys.argv[1:])
    """
)


def test_a_killed_export_leaves_the_old_module_and_the_next_run_cleans_up(
    models: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "c"
    argv = ["--channels", "all", "-o", str(out), "--name", "imu"]
    assert codegen_main(["export", str(models["a"]), *argv]) == 0
    before = _contents(out)
    killed = subprocess.run(
        [sys.executable, "-c", KILLER, "export", str(models["b"]), *argv],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        check=False,
    )
    assert killed.returncode == -9, killed.stderr
    assert _contents(out) == before  # the old module, whole
    assert len(_siblings(out)) == 1  # the killed run's staging folder
    capsys.readouterr()
    assert codegen_main(["export", str(models["b"]), *argv]) == 0
    assert "removed 1 leftover(s) of an interrupted run" in capsys.readouterr().err
    assert _siblings(out) == []
    manifest = json.loads((out / "imu.manifest.json").read_text())
    new_models = {p.name: p for p in models["b"].glob("*.pt")}
    for channel in manifest["channels"]:  # every file of the new set is from the new models
        digest = hashlib.sha256(new_models[channel["model"]["file"]].read_bytes()).hexdigest()
        assert channel["model"]["sha256"] == digest
        assert digest[:16] in (out / "imu.c").read_text()


def test_the_working_directory_is_written_in_place(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "out"
    write_files_atomically({"m.h": "old"}, out)
    inode = out.stat().st_ino
    monkeypatch.chdir(out)
    write_files_atomically({"m.h": "new", "m.c": "new"}, ".")
    assert out.stat().st_ino == inode and Path.cwd() == out  # not renamed under the caller's feet
    assert _contents(out) == {"m.c": b"new", "m.h": b"new"}
