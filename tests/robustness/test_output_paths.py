"""An output that would destroy an input, or that names a directory where a file goes (or a file
where a directory goes), is one line and exit 2, before any work; the input is left as it was."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_corpus import IMPORT_OWN_CSV, valid_lines
from trainer.cli import main as trainer_main
from trainer.errors import run_cli

IMPORT = IMPORT_OWN_CSV


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["fit", "--method", "poly3", "REC", "-o", "REC"], "is also the input"),
        (["fit", "--method", "poly3", "REC", "-o", "model.csv"], "a recording's name (.csv) for the model file"),
        (["fit", "--method", "poly3", "REC", "-o", "DIR"], "a directory, not a file name for the output"),
        (["import", "REC", *IMPORT, "-o", "REC"], "is also the input"),
        (["import", "REC", *IMPORT, "-o", "DIR"], "a directory, not a file name for the output"),
        (["evaluate", "MODEL", "REC", "--out-dir", "REC"], "exists and is not a directory"),
    ],
    ids=["fit onto its recording", "fit to a .csv", "fit onto a directory", "import onto its source",
         "import onto a directory", "evaluate into a file"],
)  # fmt: skip
def test_an_output_that_cannot_be_written_there_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    rec = tmp_path / "rec.csv"
    rec.write_text("\n".join(valid_lines()) + "\n")
    model = tmp_path / "good.pt"
    assert run_cli(trainer_main, ["fit", "--method", "poly3", str(rec), "-o", str(model)]) == 0
    (tmp_path / "out.csv").mkdir()
    before = rec.read_bytes()
    capsys.readouterr()
    names = {
        "REC": str(rec),
        "MODEL": str(model),
        "DIR": str(tmp_path / "out.csv"),
        "model.csv": str(tmp_path / "m.csv"),
    }
    assert run_cli(trainer_main, [names.get(a, a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert rec.read_bytes() == before
    assert not (tmp_path / "m.csv").exists() and not any((tmp_path / "out.csv").iterdir())


def test_a_constant_output_and_cr_only_line_ends_are_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two inputs that used to pass or mislead: an output column that never varies (fitted as a
    perfect, meaningless model) and a file whose lines end in CR alone (read as one comment line)."""
    lines = valid_lines()
    constant = [*lines[:2], *(",".join([*row.split(",")[:2], "1.0"]) for row in lines[2:])]
    (tmp_path / "const.csv").write_text("\n".join(constant) + "\n")
    (tmp_path / "cr.csv").write_text("\r".join(lines) + "\r")
    for name, message in (("const.csv", "holds 1 in every row"), ("cr.csv", "end in CR alone")):
        argv = ["fit", "--method", "poly3", str(tmp_path / name), "-o", str(tmp_path / "m.pt")]
        assert run_cli(trainer_main, argv) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1 and not (tmp_path / "m.pt").exists()
    # what fit refuses, evaluate and compare refuse too (they printed an Allan improvement of nan)
    (tmp_path / "good.csv").write_text("\n".join(lines) + "\n")
    assert (
        run_cli(
            trainer_main,
            ["fit", "--method", "poly3", str(tmp_path / "good.csv"), "-o", str(tmp_path / "g.pt")],
        )
        == 0
    )
    capsys.readouterr()
    const = str(tmp_path / "const.csv")
    for argv in (
        ["evaluate", str(tmp_path / "g.pt"), const, "--out-dir", str(tmp_path / "ev")],
        ["compare", const, "--holdout", "first:0.5", "--methods", "poly3", "--out-dir", str(tmp_path / "cp")],
    ):
        assert run_cli(trainer_main, argv) == 2
        err = capsys.readouterr().err
        assert "holds 1 in every row" in err and err.count("\n") == 1, err
    assert not (tmp_path / "ev").exists() and not (tmp_path / "cp").exists()


def test_a_mavlink_telemetry_log_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A .tlog was answered with the delimited importer's "--temp COLUMN is required"."""
    log = tmp_path / "flight.tlog"
    log.write_bytes(bytes(range(256)) * 4)
    assert run_cli(trainer_main, ["import", str(log), "-o", str(tmp_path / "r.csv")]) == 2
    err = capsys.readouterr().err
    assert "a MAVLink telemetry log (.tlog) is not read" in err and err.count("\n") == 1
