"""The project's imports read from the source (ast), for the structure tests: no cycles
(tests/project/test_architecture.py) and which layer may import which (tests/project/test_layers.py).

Every import counts: module level, inside functions and under ``TYPE_CHECKING``.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("trainer", "codegen")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def sources(packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    """Module name -> file of every module of ``packages``."""
    return {module_name(p): p for pkg in packages for p in sorted((ROOT / pkg).rglob("*.py"))}


@dataclass(frozen=True)
class ImportedName:
    """One name an import statement binds: ``from X import y`` gives module X, name X.y."""

    line: int
    module: str
    name: str


def imported_names(source: str, name: str, is_package: bool) -> list[ImportedName]:
    """The absolute dotted names that module ``name`` (its text ``source``) imports anywhere."""
    package = name if is_package else name.rpartition(".")[0]
    found: list[ImportedName] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [ImportedName(node.lineno, alias.name, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            found += [ImportedName(node.lineno, base, f"{base}.{alias.name}") for alias in node.names]
    return found


def owning_module(dotted: str, modules: set[str]) -> str | None:
    """The longest project module that ``dotted`` lies in (None outside the project)."""
    while dotted and dotted not in modules:
        dotted = dotted.rpartition(".")[0]
    return dotted or None


def imports(source: str, name: str, is_package: bool, modules: set[str]) -> set[str]:
    """Project modules that module ``name`` imports (``from pkg import mod`` counts pkg and pkg.mod)."""
    found: set[str] = set()
    for imported in imported_names(source, name, is_package):
        for target in (imported.module, imported.name):
            owner = owning_module(target, modules)
            if owner is not None and owner != name:
                found.add(owner)
    return found


def import_graph(files: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the project modules it imports, for every module of ``files``."""
    modules = set(files)
    return {
        name: imports(path.read_text(encoding="utf-8"), name, path.name == "__init__.py", modules)
        for name, path in files.items()
    }
