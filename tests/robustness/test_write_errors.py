"""A failed write (full disk, file-size limit, permissions, read-only file system) is one line
naming the output, exit 2, and leaves nothing behind: no partial file, no half set, no staging."""

from __future__ import annotations

import errno
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from trainer.cli import main
from trainer.errors import UserError, output_name, run_cli
from trainer.fleet.cache import publish_unit

WRITE_ERRNOS = (errno.ENOSPC, errno.EFBIG, errno.EACCES, errno.EROFS)


def failing_write(code: int):  # type: ignore[no-untyped-def]
    def fail(*args: object, **kwargs: object) -> None:
        raise OSError(code, os.strerror(code))  # as a write() through an open file: no file name

    return fail


def everything_in(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.fixture(scope="module")
def model_and_recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("in")
    rec, model = folder / "sim.npz", folder / "poly3.pt"
    assert run_cli(main, ["simulate", "--seed", "1", "--duration", "600", "--rate", "5", "-o", str(rec)]) == 0
    assert run_cli(main, ["fit", "--method", "poly3", str(rec), "-o", str(model)]) == 0
    return model, rec


@pytest.mark.parametrize("code", WRITE_ERRNOS)
def test_simulate_write_error(
    code: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr("trainer.data.recording_io._write_npz", failing_write(code))
    out = tmp_path / "rec.npz"
    assert run_cli(main, ["simulate", "--seed", "1", "--duration", "60", "--rate", "5", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {out}: cannot write ({os.strerror(code)}); nothing was written there\n"
    assert everything_in(tmp_path) == []


def test_evaluate_writes_report_and_figures_as_a_set(
    model_and_recording: tuple[Path, Path],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The last figure fails: neither report.md nor the first figure appears."""
    model, rec = model_and_recording
    monkeypatch.setattr("trainer.scoring.allan.plot_allan", failing_write(errno.ENOSPC))
    out = tmp_path / "ev"
    assert run_cli(main, ["evaluate", str(model), str(rec), "--out-dir", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()[-1]
    assert (
        err
        == f"error: {out / 'fig13_allan.png'}: cannot write (No space left on device); nothing was written there"
    )
    assert everything_in(tmp_path) in ([], ["ev"])  # at most the empty folder


def test_fleet_unit_write_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(Path, "write_bytes", failing_write(errno.EDQUOT))
    with pytest.raises(UserError, match=r"units/U1: cannot write \(Disk quota exceeded\)"):
        publish_unit(tmp_path, "U1", {"result.json": b"{}", "poly3/model.pt": b"x"})
    assert everything_in(tmp_path) == ["units"]


def test_other_os_errors_keep_their_traceback(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Only the write failures a user can fix become one line; anything else is a bug to see."""
    monkeypatch.setattr("trainer.data.recording_io._write_npz", failing_write(errno.EIO))
    with pytest.raises(OSError, match="Input/output error"):
        run_cli(
            main,
            ["simulate", "--seed", "1", "--duration", "60", "--rate", "5", "-o", str(tmp_path / "a.npz")],
        )


def test_output_name_hides_staging() -> None:
    assert output_name("out/.report.md.k2x_9q0a.part.md") == "out/report.md"
    assert output_name("a/.signoff.ab12cd34/fig.png") == "a/signoff/fig.png"
    assert output_name("units/.U1.abcdefgh.part/poly3/model.pt") == "units/U1/poly3/model.pt"
    assert output_name("plain/.hidden") == "plain/.hidden"


def test_file_size_limit_in_a_real_process(tmp_path: Path) -> None:
    """SIGXFSZ would kill the process silently: it is ignored and the EFBIG is reported."""
    out = tmp_path / "rec.csv"
    limit = 4096

    def limit_file_size() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    done = subprocess.run(
        [sys.executable, "-m", "trainer.cli", "simulate", "--seed", "1", "--duration", "600", "-o", str(out)],
        preexec_fn=limit_file_size,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr == f"error: {out}: cannot write (File too large); nothing was written there\n"
    assert everything_in(tmp_path) == []
