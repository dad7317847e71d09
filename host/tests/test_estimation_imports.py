"""The estimation room has no import circle: from ``eelbot report`` into the fit and back, every
module of ``eelhost.estimation`` is entered once (docs/architecture.md, the estimation room).

The imports are read with ``ast``, so the ones inside functions and ``TYPE_CHECKING`` blocks count
too: a deferred import that only hides a circle is a circle.
"""

from __future__ import annotations

import ast
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
