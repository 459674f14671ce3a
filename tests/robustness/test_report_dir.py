"""A report directory holds one command's report (:mod:`trainer.report_dir`): a comparison run again
with fewer methods leaves no model or figure of the earlier run beside its report, another command's
report is refused before any work, and the user's own files there are never touched."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_corpus import valid_lines
from trainer.cli import main as trainer_main
from trainer.errors import run_cli


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    path = tmp_path / "rec.csv"
    path.write_text("\n".join(valid_lines()) + "\n")
    return path


def _compare(recording: Path, out: Path, methods: str, *extra: str) -> int:
    argv = [
        "compare",
        str(recording),
        "--holdout",
        "0.5",
        "--methods",
        methods,
        "--out-dir",
        str(out),
        *extra,
    ]
    return run_cli(trainer_main, argv)


def _files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}


def test_a_second_comparison_leaves_none_of_the_first_one_s_files_it_does_not_write(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cmp"
    assert _compare(recording, out, "poly3,pla") == 0
    assert {"models/poly3.pt", "models/pla.pt"} <= _files(out)
    (out / "notes.txt").write_text("the user's own file\n")
    capsys.readouterr()
    assert _compare(recording, out, "poly3") == 0
    assert "models/pla.pt" in capsys.readouterr().err  # said
    fresh = tmp_path / "fresh"
    assert _compare(recording, fresh, "poly3") == 0
    assert _files(out) == _files(fresh) | {"notes.txt"}  # exactly a fresh run's files, and the user's


def test_a_cross_validated_comparison_after_a_held_out_one_keeps_no_model_of_it(
    recording: Path, tmp_path: Path
) -> None:
    out = tmp_path / "cmp"
    assert _compare(recording, out, "poly3") == 0
    assert (
        run_cli(trainer_main, ["compare", str(recording), "--methods", "poly3", "--out-dir", str(out)]) == 0
    )
    assert not (out / "models").exists() and (out / "crossval.json").is_file()


def test_another_command_s_report_is_refused_before_any_work(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cmp"
    assert _compare(recording, out, "poly3") == 0
    before = {name: (out / name).read_bytes() for name in _files(out)}
    capsys.readouterr()
    argv = ["evaluate", str(out / "models" / "poly3.pt"), str(recording), "--out-dir", str(out)]
    assert run_cli(trainer_main, argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds the report of trainer compare" in err
    assert {name: (out / name).read_bytes() for name in _files(out)} == before
    # an evaluation into its own directory, twice, is fine
    argv[-1] = str(tmp_path / "ev")
    assert run_cli(trainer_main, argv) == 0 and run_cli(trainer_main, argv) == 0


def test_a_directory_without_the_list_is_written_as_before(recording: Path, tmp_path: Path) -> None:
    """A directory of an earlier version (no list) or the user's: nothing in it is removed."""
    out = tmp_path / "old"
    (out / "models").mkdir(parents=True)
    (out / "models" / "dlstm.pt").write_bytes(b"an earlier version's model")
    assert _compare(recording, out, "poly3") == 0
    assert (out / "models" / "dlstm.pt").read_bytes() == b"an earlier version's model"
