"""README copy-paste: every command line of its bash blocks parses, unless it says it is a template;
the numbers quoted from the bundled real run match a fresh run (scripts/doc_numbers.py)."""

from __future__ import annotations

import importlib.util
import re
import shlex
import sys
from pathlib import Path

import pytest

from codegen.cli import build_parser as codegen_parser
from tests.repo import REPO_ROOT
from trainer.cli import build_parser as trainer_parser

ROOT = REPO_ROOT
README = ROOT / "README.md"
TEMPLATE = "# template:"  # how a README line says it needs the reader's own files or ids
PARSERS = {"trainer": trainer_parser, "codegen": codegen_parser}
_SPEC = importlib.util.spec_from_file_location("doc_numbers", ROOT / "scripts" / "doc_numbers.py")
assert _SPEC is not None and _SPEC.loader is not None
doc_numbers = importlib.util.module_from_spec(_SPEC)
sys.modules[_SPEC.name] = doc_numbers  # its dataclasses look their module up
_SPEC.loader.exec_module(doc_numbers)


def readme_commands() -> list[str]:
    """Each command line of README's bash blocks (continuations joined), templates left out."""
    blocks = re.findall(r"^```bash\n(.*?)^```", README.read_text(), flags=re.S | re.M)
    lines = "\n".join(blocks).replace("\\\n", " ").splitlines()
    return [line for line in lines if line.strip() and TEMPLATE not in line]


def test_readme_has_commands_and_templates() -> None:
    commands = readme_commands()
    assert len(commands) >= 15 and any(TEMPLATE in line for line in README.read_text().splitlines())
    assert not [c for c in commands if re.search(r"\bmy_|=ID\b|\bID,", c)], "a placeholder without a mark"


@pytest.mark.parametrize("line", readme_commands())
def test_every_readme_command_parses(line: str) -> None:
    argv = shlex.split(line, comments=True)
    program = argv[0]
    if program in PARSERS:
        try:
            PARSERS[program]().parse_args(argv[1:])
        except SystemExit as exc:  # argparse's way of refusing
            pytest.fail(f"{line!r} does not parse (exit {exc.code})")
    elif program in ("python", "python3"):
        assert (ROOT / argv[1]).is_file(), line
    elif program.startswith("scripts/"):
        assert (ROOT / program).is_file(), line
    else:
        assert program in ("mkdir", "make"), f"unknown program in the README: {line!r}"


def test_quoted_cheap_numbers_match_a_fresh_run(real_run: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The cubic and PLA figures of the real run quoted in README/docs (a few seconds); the physics
    ones need ``--slow`` (below)."""
    monkeypatch.setattr(doc_numbers, "REAL", real_run)
    values = doc_numbers.measure(doc_numbers.FORMATS, slow=False)
    assert values, "nothing measured"
    quoted = 0
    for path in doc_numbers.DOCS:
        for m in doc_numbers.markers(path.read_text()):
            if m["key"] in values:
                quoted += 1
                assert m["text"] == format(values[m["key"]], m["fmt"] or doc_numbers.FORMATS[m["key"]]), (
                    f"{path.name}: {m['key']} quotes {m['text']}; run python scripts/doc_numbers.py"
                )
    assert quoted >= 10
    assert doc_numbers.unknown_keys(doc_numbers.DOCS) == []


@pytest.mark.slow  # the physics fits: about a minute of CPU
def test_quoted_numbers_match_a_fresh_run_including_physics(
    real_run: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(doc_numbers, "REAL", real_run)
    assert doc_numbers.main(["--check", "--slow"]) == 0, capsys.readouterr().out
