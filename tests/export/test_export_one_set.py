"""An export of module NAME into a folder leaves NAME's files as one set: its own.

A re-export without ``--blob`` left the previous export's ``NAME.cal.bin`` beside the new module; both
modules carry the same ``NAME_MODULE_ID`` (the layout's), so the new module's ``NAME_load`` accepted the
blob of the earlier calibration and a factory flashing "the blob in the export folder" shipped it
(``codegen verify`` failed: "the calibration of other models"). The files another export or the user
put there stay.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from codegen.cli import main as codegen_main
from tests.cli_capture import run_captured
from tests.imu_checks import accel_gyro_columns
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording

NAME = "imu_tdc"
BLOB = f"{NAME}.cal.bin"  # docs/imu-module.md: the blob --blob writes beside the data-only module
NOTES = "the unit's notes, not an export's\n"


@pytest.fixture(scope="module")
def fits(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two calibrations of one layout (poly3 on both channels, about two references) and the recording."""
    root = tmp_path_factory.mktemp("one_set")
    rec = root / "rec.csv"
    write_recording(Recording(accel_gyro_columns(6), {"sample_rate_hz": "2"}, "one-set"), rec)
    for key, extra in (("a", []), ("b", ["--tref", "25"])):
        argv = ["fit", "--method", "poly3", str(rec), "--channels", "all", *extra, "-o", str(root / key)]
        assert trainer_main(argv) == 0
    return {"a": root / "a", "b": root / "b", "rec": rec}


def _written(out: str) -> set[str]:
    """The file names the export's "wrote OUT/{a, b, ...}" line gives."""
    match = re.search(r"^wrote [^{]*\{([^}]*)\}", out, re.MULTILINE)
    assert match is not None, out
    return {name.strip() for name in match.group(1).split(",")}


def _own_files(out_dir: Path) -> set[str]:
    return {p.name for p in out_dir.iterdir() if p.name.startswith(f"{NAME}.")}


def _export(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    return run_captured(codegen_main, capsys, "export", *args)


def _module_with_blob(capsys: pytest.CaptureFixture[str], fitted: Path, out: Path) -> None:
    """The IMU module of every channel fitted in ``fitted``, with its calibration blob, in ``out``."""
    code, _, err = _export(capsys, str(fitted), "--channels", "all", "-o", str(out), "--name", NAME, "--blob")
    assert code == 0, err


def test_a_re_export_without_blob_removes_the_earlier_blob_and_keeps_foreign_files(
    fits: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "X"
    code, _, err = _export(
        capsys, str(fits["a"]), "--channels", "all", "-o", str(out), "--name", NAME, "--blob"
    )
    assert code == 0, err
    assert (out / BLOB).is_file()
    (out / "notes.txt").write_text(NOTES)
    other = "other_tdc"  # another module of the same folder, with its own blob
    code, _, err = _export(
        capsys, str(fits["a"]), "--channels", "all", "-o", str(out), "--name", other, "--blob"
    )
    assert code == 0, err
    other_files = {p.name: p.read_bytes() for p in out.iterdir() if p.name.startswith(f"{other}.")}
    assert f"{other}.cal.bin" in other_files
    sha_a = json.loads((out / f"{NAME}.manifest.json").read_text())["calibration"]["sha256"]

    code, stdout, err = _export(capsys, str(fits["b"]), "--channels", "all", "-o", str(out), "--name", NAME)
    assert code == 0, err
    manifest = json.loads((out / f"{NAME}.manifest.json").read_text())
    assert manifest["calibration"]["sha256"] != sha_a  # a calibration of its own: the old blob is not it
    # NAME's files are exactly this export's: no blob of the earlier one beside its module
    assert _own_files(out) == {n for n in _written(stdout) if n.startswith(f"{NAME}.")}
    assert not (out / BLOB).exists()
    removed = [line for line in err.splitlines() if BLOB in line]
    assert len(removed) == 1 and "removed" in removed[0] and removed[0].startswith("note: "), err
    # what is not NAME's stays as it was: the user's notes, the other module and its blob
    assert (out / "notes.txt").read_text() == NOTES
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name.startswith(f"{other}.")} == other_files
    # the folder now verifies against the models it was exported from (it failed on the stale blob)
    code, _, err = run_captured(
        codegen_main, capsys, "verify", str(fits["b"]), str(out), str(fits["rec"]), "--channels", "all"
    )
    assert code == 0, err


def test_a_one_channel_module_over_an_imu_module_with_blob_removes_the_blob(
    fits: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "one"
    _module_with_blob(capsys, fits["a"], out)
    code, stdout, err = _export(capsys, str(fits["b"] / "accel0_z.pt"), "-o", str(out), "--name", NAME)
    assert code == 0, err
    assert not (out / BLOB).exists() and f"removed {BLOB}" in err
    assert _own_files(out) == {n for n in _written(stdout) if n.startswith(f"{NAME}.")}


def test_a_blob_alone_replaces_the_blob_and_keeps_the_module_it_is_for(
    fits: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The factory path: one data-only module, each unit's blob written beside it."""
    out = tmp_path / "factory"
    _module_with_blob(capsys, fits["a"], out)
    module = {n: (out / n).read_bytes() for n in _own_files(out) - {BLOB}}
    old_blob = (out / BLOB).read_bytes()
    code, _, err = _export(
        capsys,
        str(fits["b"]),
        "--channels",
        "all",
        "-o",
        str(out),
        "--name",
        NAME,
        "--format",
        "calibration-blob",
    )
    assert code == 0, err
    assert {n: (out / n).read_bytes() for n in _own_files(out) - {BLOB}} == module
    assert (out / BLOB).read_bytes() != old_blob and "removed" not in err


def test_a_refused_export_leaves_the_earlier_set_whole(
    fits: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "kept"
    _module_with_blob(capsys, fits["a"], out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    code, stdout, err = _export(
        capsys, str(fits["b"]), "--channels", "all", "-o", str(out), "--name", NAME, "--rate", "-1"
    )
    assert code == 2 and stdout == "" and len(err.strip().splitlines()) == 1, err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
