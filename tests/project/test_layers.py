"""Layer rules, beside the cycle test of tests/project/test_architecture.py: ``trainer/commands`` sits on
top (only the ``trainer`` entry module dispatches to it), ``codegen`` never imports it, no module
loads another by file path (an import no checker sees, which hid a codegen -> firmware_c -> codegen
loop), and no package imports another package's private names.

Each rule is a function of the import graph or of a module's text, so that the leaks it exists for
are shown to be reported (``test_each_leak_is_reported_and_its_fix_is_not``) and the repository
to be free of them.
"""

from __future__ import annotations

import ast
import functools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.import_graph import ROOT, import_graph, imported_names, imports, owning_module, sources

COMMANDS = "trainer.commands"
CLI_ENTRIES = frozenset({"trainer.cli"})  # dispatches to one module per sub-command
# Calls that run a file's code without importing it by name.
LOADERS_BY_PATH = frozenset({"spec_from_file_location", "SourceFileLoader", "run_path", "exec", "execfile"})
# Where rule (c) applies: the packages, and firmware_c/ (not a package: its Python would be loaded by path).
PATH_LOAD_DIRS = ("trainer", "codegen", "firmware_c")


def _within(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def command_imports(graph: Mapping[str, set[str]]) -> list[str]:
    """Rule (a): edges into ``trainer.commands`` from outside it and the CLI entry modules."""
    return sorted(
        f"{source} -> {target}"
        for source, targets in graph.items()
        for target in targets
        if _within(target, COMMANDS) and not _within(source, COMMANDS) and source not in CLI_ENTRIES
    )


def codegen_command_imports(graph: Mapping[str, set[str]]) -> list[str]:
    """Rule (b): edges from ``codegen`` into ``trainer.commands``."""
    return sorted(
        f"{source} -> {target}"
        for source, targets in graph.items()
        for target in targets
        if _within(source, "codegen") and _within(target, COMMANDS)
    )


def loads_by_path(source: str) -> list[str]:
    """Rule (c): calls that load code by file path (``importlib.util.spec_from_file_location``,
    ``SourceFileLoader``, ``runpy.run_path``, ``exec``), as ``line: name``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call):
            func = node.func
            called = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if called in LOADERS_BY_PATH:
                found.append((node.lineno, called))
    return [f"{line}: {called}" for line, called in sorted(found)]


def package_of(module: str, packages: set[str]) -> str:
    """The unit a private name is private to: ``trainer.<subpackage>`` or the top-level package."""
    package = module if module in packages else module.rpartition(".")[0]
    return ".".join(package.split(".")[:2])


def private_imports(
    source: str, name: str, is_package: bool, modules: set[str], packages: set[str]
) -> list[str]:
    """Rule (d): underscore-private names (``_x``, not ``__x__``) imported from another package."""
    found = []
    for imported in imported_names(source, name, is_package):
        parts = imported.name.split(".")
        private = [i for i, part in enumerate(parts) if part.startswith("_") and not part.endswith("__")]
        owner = owning_module(".".join(parts[: private[0]]), modules) if private else None
        if owner is not None and package_of(owner, packages) != package_of(name, packages):
            found.append(f"{name}:{imported.line}: {imported.name}")
    return found


@dataclass(frozen=True)
class Tree:
    """The repository's modules, packages and import graph."""

    files: dict[str, Path]
    packages: set[str]
    graph: dict[str, set[str]]

    def violations(self, module: str, source: str) -> dict[str, list[str]]:
        """Each rule's report (a-d) with ``module`` reading ``source`` and the rest of the tree as is."""
        modules = set(self.files) | {module}
        is_package = module in self.packages
        graph = {**self.graph, module: imports(source, module, is_package, modules)}
        return {
            "a": command_imports(graph),
            "b": codegen_command_imports(graph),
            "c": loads_by_path(source),
            "d": private_imports(source, module, is_package, modules, self.packages),
        }


@functools.cache
def _tree() -> Tree:
    files = sources()
    packages = {name for name, path in files.items() if path.name == "__init__.py"}
    return Tree(files, packages, import_graph(files))


_PATH_LOAD = """import importlib.util
def _cortex_m():
    spec = importlib.util.spec_from_file_location("cortex_m", ROOT / "firmware_c" / "cortex_m.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
"""
# The leaks of issue 25 as they were written, the rules that must report each, and the fix.
LEAKS = {
    "methods imports commands.method_options": (
        "trainer.methods",
        "from trainer.commands.method_options import DLSTM_OPTIONS, OptionGroup\n",
        {"a"},
        "from trainer.options.methods import DLSTM_OPTIONS, OptionGroup\n",
    ),
    "codegen.cli imports commands.channel_options": (
        "codegen.cli",
        "from trainer.commands.channel_options import add_channels_option\n",
        {"a", "b"},
        "from trainer.options.channels import add_channels_option\n",
    ),
    "fleet.options imports commands.import_cmd in a function": (
        "trainer.fleet.options",
        "def _import_args():\n    from trainer.commands import import_cmd\n    return import_cmd\n",
        {"a"},
        "def _import_args():\n    from trainer.options import importing\n    return importing\n",
    ),
    "imu_verify loads firmware_c/cortex_m.py by path": (
        "codegen.imu_verify",
        _PATH_LOAD,
        {"c"},
        "from codegen import cortex_m as cm\n",
    ),
    "codegen imports the importer's private _resample": (
        "codegen.rate",
        "from trainer.data.importer import _resample as resample_columns\n",
        {"d"},
        "from trainer.data.importer import resample_columns\n",
    ),
}


@pytest.mark.parametrize("leak", LEAKS)
def test_each_leak_is_reported_and_its_fix_is_not(leak: str) -> None:
    module, source, rules, fixed = LEAKS[leak]
    reported = _tree().violations(module, source)
    assert {rule for rule, found in reported.items() if found} == rules
    assert not any(_tree().violations(module, fixed).values())


def test_every_path_loader_is_reported() -> None:
    source = "import runpy\nfrom importlib.machinery import SourceFileLoader\n"
    source += (
        "SourceFileLoader('m', 'm.py').load_module()\nrunpy.run_path('m.py')\nexec(open('m.py').read())\n"
    )
    assert loads_by_path(source) == ["3: SourceFileLoader", "4: run_path", "5: exec"]


def test_a_private_name_within_its_own_package_is_allowed() -> None:
    tree = _tree()
    source = "from trainer.data.importer import _resample\n"
    assert not private_imports(source, "trainer.data.flightlog_import", False, set(tree.files), tree.packages)


def test_only_the_cli_imports_the_commands() -> None:
    found = command_imports(_tree().graph)
    assert not found, "imports of trainer.commands from below it:\n" + "\n".join(found)


def test_codegen_never_imports_the_commands() -> None:
    assert not codegen_command_imports(_tree().graph)


def test_no_module_loads_another_by_file_path() -> None:
    files = [p for folder in PATH_LOAD_DIRS for p in sorted((ROOT / folder).rglob("*.py"))]
    found = [
        f"{path.relative_to(ROOT)}:{line}"
        for path in files
        for line in loads_by_path(path.read_text("utf-8"))
    ]
    assert not found, "loads by file path:\n" + "\n".join(found)
    assert len(files) > 50  # the walk saw the tree


def test_no_private_name_is_imported_across_packages() -> None:
    tree = _tree()
    found = [
        line
        for name, path in tree.files.items()
        for line in private_imports(
            path.read_text("utf-8"), name, name in tree.packages, set(tree.files), tree.packages
        )
    ]
    assert not found, "private names imported from another package:\n" + "\n".join(found)


def test_tests_and_benches_import_no_private_names() -> None:
    """What a test or a bench needs of a module is its public interface (rule (d) from outside)."""
    tree = _tree()
    modules = set(tree.files)
    found = [
        line
        for folder in ("tests", "bench")
        for path in sorted((ROOT / folder).rglob("*.py"))
        for line in private_imports(
            path.read_text("utf-8"), f"{folder}.{path.stem}", False, modules, tree.packages
        )
    ]
    assert not found, "private names imported by tests or benches:\n" + "\n".join(found)
