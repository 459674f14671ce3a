"""The comparison report's "How to read the scores" says only what holds for this comparison: the
persistence row's Allan score as the report's own Table 1 gives it (a real run's report said it beat
every method and the paper's 96.68 % while its table gave it 87.43 %), ground truth and the oracle
row only where the validation data has them."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.cli_corpus import valid_lines
from trainer.cli import main as trainer_main
from trainer.errors import run_cli


def _how_to_read(tmp_path: Path, methods: str) -> tuple[str, str]:
    rec = tmp_path / "rec.csv"
    rec.write_text("\n".join(valid_lines()) + "\n")
    out = tmp_path / methods.replace(",", "_")
    argv = ["compare", str(rec), "--holdout", "0.5", "--methods", methods, "--out-dir", str(out)]
    assert run_cli(trainer_main, argv) == 0
    report = (out / "report.md").read_text()
    return report.split("## How to read the scores")[1].split("## ")[0], (out / "table1.txt").read_text()


def test_the_persistence_score_quoted_is_the_table_s(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text, table = _how_to_read(tmp_path, "poly3,pla,persistence")
    quoted = re.search(r"it scores ([0-9.]+) % on average", text)
    assert quoted is not None, text
    aver = next(line for line in table.splitlines() if line.startswith("Aver"))
    columns = next(line for line in table.splitlines() if "Validation Data" in line).split()
    values = aver.split()[2:]  # "Aver (%)" then one improvement per method, in the header's order
    methods = [c for c in columns if c not in ("Validation", "Data", "Improvement", "(%)")]
    assert quoted.group(1) == values[methods.index("persistence")]
    assert "ground truth (`true_drift_mg`)" not in text and "oracle" not in text  # a real run has neither


def test_without_persistence_the_report_does_not_speak_of_it(tmp_path: Path) -> None:
    text, _ = _how_to_read(tmp_path, "poly3,pla")
    assert "persistence" not in text
