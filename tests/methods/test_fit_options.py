"""``trainer fit`` refuses an option of another method (``--effects`` with poly3, ``--remove-median``
with physics, a DLSTM's ``--temp-smoothing`` with poly3) instead of ignoring it: the user expected
it to act. Options of the fitted method and the command-wide ``--quiet`` pass."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_corpus import valid_lines
from trainer.cli import main as trainer_main
from trainer.errors import run_cli


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--method", "poly3", "--effects", "thermal_lag"], "--effects does not apply to --method poly3: it is an option of physics"),
        (["--method", "physics", "--remove-median"], "--remove-median does not apply to --method physics: it is an option of poly3"),
        (["--method", "poly3", "--temp-smoothing", "-3", "--step", "0"], "--temp-smoothing does not apply to --method poly3: it is an option of dlstm"),
        (["--method", "auto", "--intervals", "3"], "--intervals does not apply to --method auto: it is an option of pla"),
        (["--method", "poly3", "--remove-median", "--quiet"], None),
        (["--method", "pla", "--intervals", "3"], None),
    ],
)  # fmt: skip
def test_an_option_of_another_method_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str | None
) -> None:
    rec = tmp_path / "rec.csv"
    rec.write_text("\n".join(valid_lines()) + "\n")
    out = tmp_path / "m.pt"
    code = run_cli(trainer_main, ["fit", *argv, str(rec), "-o", str(out)])
    err = capsys.readouterr().err
    if message is None:
        assert code == 0 and out.is_file()
    else:
        assert code == 2 and message in err and err.count("\n") == 1 and not out.exists()
