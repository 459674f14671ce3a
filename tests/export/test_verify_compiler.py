"""``codegen verify --cc NAME`` builds with that compiler or refuses in one line; it never quietly
builds with another one (the user asked to prove the C under a given compiler)."""

from __future__ import annotations

from pathlib import Path

import pytest

from codegen.cli import main as codegen_main
from tests.cli_corpus import valid_lines
from trainer.cli import main as trainer_main
from trainer.errors import run_cli


def test_a_compiler_that_is_not_there_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec, model, module = tmp_path / "rec.csv", tmp_path / "m.pt", tmp_path / "c"
    rec.write_text("\n".join(valid_lines()) + "\n")
    assert run_cli(trainer_main, ["fit", "--method", "poly3", str(rec), "-o", str(model)]) == 0
    assert run_cli(codegen_main, ["export", str(model), "-o", str(module)]) == 0
    capsys.readouterr()
    argv = ["verify", str(model), str(module), str(rec), "--cc", "no-such-cc-1234"]
    assert run_cli(codegen_main, argv) == 2
    err = capsys.readouterr().err
    assert err == "error: --cc no-such-cc-1234: no such compiler on PATH\n"
