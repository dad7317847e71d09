"""The estimation room has no import circle: from ``eelbot report`` into the fit and back, every
module of ``eelhost.estimation`` is entered once (docs/architecture.md, the estimation room).

The imports are read with ``ast``, so the ones inside functions and ``TYPE_CHECKING`` blocks count
too: a deferred import that only hides a circle is a circle.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOM = Path(__file__).resolve().parents[1] / "eelhost" / "estimation"
PACKAGE = "eelhost.estimation"


def room_imports() -> dict[str, set[str]]:
    """Each module of the room (by its short name) and the room's modules it imports."""
    modules = {p.stem for p in ROOM.glob("*.py") if p.stem != "__init__"}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module in modules:
        tree = ast.parse((ROOM / f"{module}.py").read_text(), f"{module}.py")
        for node in ast.walk(tree):  # every node: imports inside functions and ifs too
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                # ``from eelhost.estimation import cluster`` imports the module cluster
                names = [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
            elif isinstance(node, ast.ImportFrom) and node.level:
                pytest.fail(f"{module}.py: a relative import (the room imports absolutely)")
            else:
                continue
            for name in names:
                parts = name.split(".")
                if parts[:2] == PACKAGE.split(".") and len(parts) > 2 and parts[2] in modules:
                    if parts[2] != module:
                        graph[module].add(parts[2])
    return graph


def circle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle of ``graph`` (its modules in order, the first repeated last), or None."""
    state: dict[str, int] = {}  # 1: on the depth-first path, 2: finished

    def visit(node: str, path: list[str]) -> list[str] | None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt):], nxt]
            if nxt not in state and (found := visit(nxt, [*path, nxt])):
                return found
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start, [start])):
            return found
    return None


def test_no_module_of_the_estimation_room_imports_itself_back_through_others():
    found = circle(room_imports())
    assert found is None, "import circle in eelhost.estimation: " + " -> ".join(found or [])


def test_the_circle_finder_sees_deferred_imports_and_real_circles():
    # the reading itself: a finder that missed deferred imports or circles would pass on nothing
    graph = room_imports()
    assert "figures" in graph["report"]  # imported inside run_report (matplotlib is slow)
    assert {"evaluate", "optimise"} <= graph["methods"]
    assert circle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert circle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_report_reaches_the_fit_the_evaluator_and_the_coefficients_file():
    # the path the layout serves: eelbot report into the fit and back, every step one way
    graph = room_imports()
    reached, todo = set(), ["report"]
    while todo:
        module = todo.pop()
        if module not in reached:
            reached.add(module)
            todo.extend(graph[module])
    assert {"methods", "evaluate", "batch_backend", "coefficients_file", "space"} <= reached


REPO = ROOM.parents[2]
IMPORTERS = ("host", "sim", "tools", "scripts", "hil_tests", "benchmarks")


def defined_names(source: str) -> set[str]:
    """The names a module defines at its top level (functions, classes, assignments), not imports."""
    names: set[str] = set()
    for node in ast.parse(source).body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                names.update(n.id for n in ast.walk(target) if isinstance(n, ast.Name))
    return names


def borrowed_imports(source: str, where: str, owners: dict[str, set[str]]) -> list[str]:
    """Each ``from eelhost.estimation.M import name`` of ``source`` where M does not define name.

    Also each ``import eelhost.estimation.M`` of a module M the room does not have.
    """
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[:2] == PACKAGE.split(".") and len(parts) > 2 and parts[2] not in owners:
                    found.append(f"{where}:{node.lineno}: {alias.name} is not a module of the room")
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            parts = node.module.split(".")
            if parts[:2] != PACKAGE.split(".") or len(parts) != 3:
                continue
            for alias in node.names:
                if parts[2] not in owners:
                    found.append(f"{where}:{node.lineno}: {node.module} is not a module of the room")
                elif alias.name not in owners[parts[2]]:
                    found.append(f"{where}:{node.lineno}: {alias.name} from {node.module}, "
                                 "which does not define it")
    return found


def test_every_estimation_name_is_imported_from_the_module_that_defines_it():
    # one import path per name (docs/architecture.md, the estimation room): no re-export shims
    owners = {p.stem: defined_names(p.read_text()) for p in ROOM.glob("*.py") if p.stem != "__init__"}
    found = []
    for doc in sorted((REPO / "docs").glob("*.md")) + [REPO / "README.md"]:
        for block in re.findall(r"```python\n(.*?)```", doc.read_text(), re.DOTALL):
            if f"{PACKAGE}." in block:  # the docs' examples import from the owners too
                found += borrowed_imports(block, str(doc.relative_to(REPO)), owners)
    for top in IMPORTERS:
        for path in sorted((REPO / top).rglob("*.py")) if (REPO / top).is_dir() else []:
            text = path.read_text()
            if ".venv" not in path.parts and f"{PACKAGE}." in text:  # parse only the importers
                found += borrowed_imports(text, str(path.relative_to(REPO)), owners)
    assert not found, "\n".join(found)


def test_the_owner_check_sees_a_re_exported_name():
    owners = {"space": defined_names("from x import y\nclass ParameterSpace: ...\nN: int = 2\n")}
    assert owners["space"] == {"ParameterSpace", "N"}
    assert borrowed_imports("from eelhost.estimation.space import ParameterSpace, N", "t", owners) == []
    assert borrowed_imports("def f():\n    from eelhost.estimation.space import y\n", "t", owners) == [
        "t:2: y from eelhost.estimation.space, which does not define it"]
    assert borrowed_imports("from eelhost.estimation.parameters import z", "t", owners) == [
        "t:1: eelhost.estimation.parameters is not a module of the room"]
    assert borrowed_imports("import eelhost.estimation.parameters", "t", owners) == [
        "t:1: eelhost.estimation.parameters is not a module of the room"]
