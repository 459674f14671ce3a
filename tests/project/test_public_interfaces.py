"""A package reaches another only through its public interface: trainer/greybox imports nothing of
the mismatch finder but ``trainer.diagnose.api`` (the finder's modules may be split or renamed by
changing that one list)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import trainer.diagnose.api
from tests.repo import REPO_ROOT

ROOT = REPO_ROOT

# package -> (the package it uses, the one module of it that it may import)
INTERFACES = {"trainer/greybox": ("trainer.diagnose", "trainer.diagnose.api")}


def imported_modules(path: Path) -> set[str]:
    """Absolute module names imported anywhere in ``path`` (module level and inside functions)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
    return found


@pytest.mark.parametrize("package", sorted(INTERFACES))
def test_a_package_imports_the_other_only_through_its_interface(package: str) -> None:
    used, interface = INTERFACES[package]
    leaks = {
        f"{path.relative_to(ROOT)}: {name}"
        for path in sorted((ROOT / package).rglob("*.py"))
        for name in imported_modules(path)
        if (name == used or name.startswith(used + ".")) and not name.startswith(interface)
    }
    assert leaks == set()


def test_the_rule_sees_a_leak(tmp_path: Path) -> None:
    """The parser finds both forms of a private import (the test above can fail)."""
    leak = tmp_path / "leak.py"
    leak.write_text(
        "def f():\n    from trainer.diagnose.model import Term\n    import trainer.diagnose.gls\n"
    )
    assert {"trainer.diagnose.model", "trainer.diagnose.gls"} <= imported_modules(leak)


def test_the_interface_exports_what_it_declares() -> None:
    assert all(hasattr(trainer.diagnose.api, name) for name in trainer.diagnose.api.__all__)
