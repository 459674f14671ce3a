"""An output that would destroy an input, or that names a directory where a file goes (or a file
where a directory goes), is one line and exit 2, before any work; the input is left as it was."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_corpus import valid_lines
from trainer.cli import main as trainer_main
from trainer.errors import run_cli

IMPORT = ["--temp", "temp_c", "--accel", "accel_mg", "--time", "time_s"]


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
