"""The structure the code relies on: no import cycles, and each catalogue identifier written in one
place (its definition module), so that adding an effect is one new definition. Which layer may
import which: tests/project/test_layers.py."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from tests.import_graph import ROOT, import_graph, sources
from trainer.physics import catalogue


def test_no_import_cycles_between_project_modules() -> None:
    graph = import_graph(sources())
    # A package's __init__ importing its own submodules is not a cycle of meaning: drop the edges
    # from a package to its children and from a child to its own package (Python runs __init__ first).
    for name, targets in graph.items():
        graph[name] = {t for t in targets if not t.startswith(name + ".") and not name.startswith(t + ".")}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycle = [*stack[stack.index(nxt) :], nxt]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module)
    assert len(graph) > 50  # the walk saw the whole tree


def test_each_catalogue_identifier_is_written_only_in_its_definition() -> None:
    identifiers = [d.identifier for d in (*catalogue.EFFECTS.values(), *catalogue.NOISE.values())]
    alternatives = "|".join(map(re.escape, identifiers))
    pattern = re.compile(rf"""["']({alternatives})["']""")
    catalogue_dir = ROOT / "trainer" / "physics" / "catalogue"
    offenders = [
        f"{path.relative_to(ROOT)}:{line_no}: {line.strip()}"
        for path in sources().values()
        if catalogue_dir not in path.parents
        for line_no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if pattern.search(line)
    ]
    assert not offenders, "identifier strings outside the catalogue:\n" + "\n".join(offenders)
    assert len(identifiers) == len(set(identifiers)) >= 15


def _code_names(path: Path) -> list[tuple[int, str]]:
    """``(line, name)`` of what a module's code names: identifiers, attributes, imported names and
    modules, and string constants that are one word (prose in strings, docstrings and comments is
    left out)."""
    names: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Name):
            names.append((node.lineno, node.id))
        elif isinstance(node, ast.Attribute):
            names.append((node.lineno, node.attr))
        elif isinstance(node, ast.ImportFrom):
            names += [(node.lineno, node.module or "")] + [
                (node.lineno, a.asname or a.name) for a in node.names
            ]
        elif isinstance(node, ast.Import):
            names += [(node.lineno, a.asname or a.name) for a in node.names]
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and re.fullmatch(r"[\w.]+", node.value)
        ):
            names.append((node.lineno, node.value))
    return names


def test_generic_physics_code_names_no_effect() -> None:
    """The physics compensator and the C export loop over the registries (catalogue.EFFECTS and the
    streamed effects, trainer/physics/catalogue/streamed.py): no code of trainer/greybox or codegen
    names an effect, by its identifier or by importing its module (``<effect>.py``,
    ``<effect>_stream.py``). The bias polynomial is the compensator's backbone (catalogue.BACKBONE)."""
    identifiers = [k for k in catalogue.EFFECTS if k != catalogue.BACKBONE]
    modules = [f"{name}_stream" for name in identifiers] + identifiers
    word = re.compile(rf"\b({'|'.join(map(re.escape, modules))})\b")
    generic = [ROOT / "trainer" / "greybox", ROOT / "codegen"]
    offenders = [
        f"{path.relative_to(ROOT)}:{line}: {name}"
        for path in sources().values()
        if any(folder in path.parents for folder in generic)
        for line, name in _code_names(path)
        if word.search(name)
    ]
    assert not offenders, "effects named in generic physics code:\n" + "\n".join(offenders)
    assert len(identifiers) >= 10
