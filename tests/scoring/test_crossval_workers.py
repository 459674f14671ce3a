"""The cross-validation's fits on worker processes (``--jobs``): the same figures as in this process."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import dask
import numpy as np
import pytest

from tests.scoring.test_crossval import chamber_run
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import UserError, run_cli
from trainer.fitting import fit_compensator
from trainer.fleet.cluster import TaskMap, task_map
from trainer.scoring.crossval import cross_validate


def figures(cv: object) -> dict[str, object]:
    """Every figure of a cross-validation except the fit times (which no two runs share)."""
    data = cv.to_dict()  # type: ignore[attr-defined]
    for method in data["methods"].values():
        method.pop("fit_seconds", None)
    return data


def fitters() -> dict[str, object]:
    return {
        "poly3": lambda train: fit_compensator("poly3", train),
        "pla": lambda train: fit_compensator("pla", train),
    }


@pytest.fixture(scope="module")
def two_workers() -> Iterator[TaskMap]:
    """One LocalCluster of two workers for the module's tests (it starts in seconds)."""
    with task_map(2) as tasks:
        yield tasks


def test_tasks_run_in_other_processes_and_come_back_in_order(two_workers: TaskMap) -> None:
    assert two_workers.parallel and two_workers.width == 2
    done: list[int] = []
    pids = two_workers.map(
        lambda task: (task, os.getpid()),
        list(range(6)),
        done=lambda count, _task, _result: done.append(count),
    )
    assert [task for task, _ in pids] == list(range(6))
    assert os.getpid() not in {pid for _, pid in pids}
    assert done == list(range(1, 7))


def test_fits_on_two_workers_give_the_figures_of_one(two_workers: TaskMap) -> None:
    rec = chamber_run()
    rec = Recording(  # a drift no polynomial of the folds fits exactly
        {**rec.columns, "accel_mg": rec.accel_mg + 0.3 * np.sin(3.0 * rec.temp_c / 20.0)},
        dict(rec.meta),
        rec.source,
    )
    # "stateful" sends poly3's folds to the workers (the imputed run, as physics is trained)
    here = cross_validate(rec, fitters(), stateful={"poly3"}, smoothing_s=0.5)  # type: ignore[arg-type]
    lines: list[str] = []
    there = cross_validate(
        rec,
        fitters(),  # type: ignore[arg-type]
        stateful={"poly3"},
        smoothing_s=0.5,
        tasks=two_workers,
        log=lines.append,
    )
    assert figures(there) == figures(here)
    assert lines[0].startswith("6 fits of the cross-validation on 2 worker processes")
    assert sum("done" in line for line in lines) == 6


def test_a_refusal_on_a_worker_is_the_same_one_line_refusal(two_workers: TaskMap) -> None:
    def refuse(train: Recording) -> object:
        raise UserError(f"{train.source}: cannot fit this fold")

    with pytest.raises(UserError, match="cannot fit this fold"):
        cross_validate(chamber_run(), {"x": refuse}, stateful={"x"}, smoothing_s=0.5, tasks=two_workers)
    assert two_workers.map(lambda task: task + 1, [1, 2]) == [2, 3]  # the workers go on


def test_jobs_applies_to_auto_only(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    write_recording(chamber_run(), tmp_path / "run.csv")
    capsys.readouterr()
    assert run_cli(trainer_main, ["fit", "--method", "poly3", "--jobs", "2", "run.csv", "-o", "x.pt"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--jobs applies to --method auto" in err
    assert run_cli(trainer_main, ["fit", "--method", "auto", "--jobs", "0", "run.csv", "-o", "x.pt"]) == 2
    assert "not a positive whole number" in capsys.readouterr().err
    assert not (tmp_path / "x.pt").exists()


def test_auto_writes_the_same_model_file_on_one_worker_and_on_two(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Same inputs, same bytes: the model file (whose sha256 every export carries) keeps no fit time."""
    monkeypatch.chdir(tmp_path)
    write_recording(chamber_run(), tmp_path / "run.csv")
    argv = ["fit", "--method", "auto", "--candidates", "none,poly3,physics-branch-room", "run.csv"]
    assert run_cli(trainer_main, [*argv, "--jobs", "1", "-o", "one.pt"]) == 0
    assert run_cli(trainer_main, [*argv, "--jobs", "2", "-o", "two.pt"]) == 0
    assert "on 2 worker processes" in capsys.readouterr().err
    assert (tmp_path / "one.pt").read_bytes() == (tmp_path / "two.pt").read_bytes()


@pytest.mark.parametrize("shared", [{}, {"data": np.zeros(1000)}], ids=["alone", "with-shared-data"])
def test_a_worker_that_dies_is_one_line_naming_the_option(shared: dict[str, object]) -> None:
    """A worker killed (the kernel's OOM killer, say) is a refusal that says what to do, not a trace;
    so is every worker killed, which loses the data sent to them (the task is then cancelled)."""
    import distributed  # noqa: F401  (its config defaults loaded before the set below, which restores them after)

    with (
        dask.config.set({"distributed.scheduler.allowed-failures": 0}),
        task_map(2, option="--jobs") as tasks,
        pytest.raises(UserError) as refused,
    ):
        tasks.map(lambda task, **_: os._exit(3), [1, 2], shared=shared)
    message = str(refused.value)
    assert (
        "a worker process died" in message
        and "each of the 2 workers" in message
        and "give --jobs 1" in message
    )


KILLED_WORKERS_SCRIPT = """
import multiprocessing, os, sys
import dask, distributed
from trainer.errors import UserError
from trainer.fleet import cluster
from trainer.fleet.cluster import task_map

def main():
    if sys.argv[1] == "unfiltered":
        cluster.quiet_resource_tracker = lambda: None
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        try:
            with task_map(2, option="--jobs") as tasks:
                # a worker killed while it holds a semaphore (torch and the finder's libraries do)
                tasks.map(lambda task, **_: (multiprocessing.Semaphore(), os._exit(3)), [1, 2])
        except UserError as refusal:
            print(refusal, file=sys.stderr)
            sys.exit(2)

if __name__ == "__main__":
    main()
"""


def test_killed_workers_leave_the_one_line_refusal_alone_on_stderr(tmp_path: Path) -> None:
    """The semaphores a killed worker leaves are freed by multiprocessing's tracker at exit, which
    used to add its two-line warning under the refusal. A fresh interpreter: the tracker is
    process-wide and may already run in this one. The unfiltered run shows the check can fail."""
    import subprocess
    import sys

    script = tmp_path / "killed.py"
    script.write_text(KILLED_WORKERS_SCRIPT)
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    env.pop("PYTHONWARNINGS", None)

    def stderr_of(mode: str) -> str:
        done = subprocess.run(
            [sys.executable, str(script), mode], capture_output=True, text=True, env=env, timeout=120
        )
        assert done.returncode == 2, done.stderr[-2000:]
        return done.stderr

    filtered = stderr_of("filtered")
    assert filtered.count("\n") == 1 and "a worker process died" in filtered and "give --jobs 1" in filtered
    assert "resource_tracker" in stderr_of("unfiltered")


def test_compare_per_channel_names_the_users_file_and_the_channel_in_its_outputs_and_progress(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    run = chamber_run()
    columns = {**run.columns, "accel0_z_mg": run.accel_mg, "gyro0_x_dps": 0.01 * (run.accel_mg - 1000.0)}
    write_recording(Recording(columns, dict(run.meta), "imu"), tmp_path / "imu.csv")
    capsys.readouterr()
    argv = ["compare", "imu.csv", "--channels", "all", "--methods", "poly3,pla", "--out-dir", "cv"]
    assert run_cli(trainer_main, argv) == 0
    captured = capsys.readouterr()
    progress = [line for line in captured.err.splitlines() if "cross-validation:" in line]
    assert progress and all(line.startswith("[") and " of 2] cross-validation:" in line for line in progress)
    assert any(line.startswith("[gyro0_x, channel 2 of 2] ") for line in progress)
    for channel in ("accel0_z", "gyro0_x"):
        report = (tmp_path / "cv" / channel / "report.md").read_text()
        data = (tmp_path / "cv" / channel / "crossval.json").read_text()
        for text in (report, data):
            assert "channels-" not in text and f"imu.csv (channel {channel})" in text
        assert report.splitlines()[0].count(channel) == 1, report.splitlines()[0]  # the title names it once
    assert "channels-" not in captured.out


def test_compare_holdout_writes_the_same_model_files_on_one_job_and_on_two(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A model fitted in a worker process and sent back is written byte for byte as one fitted here."""
    monkeypatch.chdir(tmp_path)
    write_recording(chamber_run(), tmp_path / "run.csv")
    argv = ["compare", "run.csv", "--holdout", "0.5", "--methods", "poly3,physics", "--quiet"]
    assert run_cli(trainer_main, [*argv, "--jobs", "1", "--out-dir", "one"]) == 0
    assert run_cli(trainer_main, [*argv, "--jobs", "2", "--out-dir", "two"]) == 0
    for name in ("poly3.pt", "physics.pt"):
        assert (tmp_path / "one" / "models" / name).read_bytes() == (
            tmp_path / "two" / "models" / name
        ).read_bytes()
