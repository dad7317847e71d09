"""docs/architecture.md's map is the territory: every name in its picture exists, every module of
eelsim and eelhost is named, and the imports keep the rules the page states (read with ``ast``,
deferred imports included)."""

from __future__ import annotations

import ast
import functools
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "architecture.md"
ROOTS = {"eelsim": REPO / "sim" / "eelsim", "eelhost": REPO / "host" / "eelhost"}
ENTRY_INDENT = 3  # a package's or top-level module's line in the picture starts in this column

PY_NAME = re.compile(r"(?<![\w./])(\w+\.py)\b")
PACKAGE_NAME = re.compile(r"(?<![\w./])(\w+/)(?![\w/])")


# ------------------------------------------------------------------------- reading the page
def section(title: str) -> str:
    text = DOC.read_text()
    start = text.index(f"## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start:end if end >= 0 else None]


def picture() -> list[str]:
    text = section("The layout in one picture")
    return text.split("```\n", 2)[1].splitlines()


def root_block(root: str) -> list[str]:
    """The picture's lines of one tree (``sim/eelsim/``), its own first line included."""
    label = ROOTS[root].relative_to(REPO).as_posix() + "/"
    lines = picture()
    first = next(i for i, line in enumerate(lines) if line.strip().startswith(label)
                 and line.index(label) == 1)
    block = [lines[first]]
    for line in lines[first + 1:]:
        if line.strip() and len(line) - len(line.lstrip()) < ENTRY_INDENT:
            break
        block.append(line)
    return block


def entries(root: str) -> Iterator[tuple[str, str]]:
    """(what the entry is, its text) for each package or top-level module line and the lines
    continuing it; what it is: ``""`` for top-level modules, else the package (``batch``)."""
    current: list[str] | None = None
    for line in root_block(root)[1:]:
        indent = len(line) - len(line.lstrip())
        if line.strip() and indent == ENTRY_INDENT:
            if current:
                yield _entry(current)
            current = [line]
        elif current is not None:
            current.append(line)
    if current:
        yield _entry(current)


def _entry(lines: list[str]) -> tuple[str, str]:
    first = lines[0].split()[0]
    return (first[:-1] if first.endswith("/") else ""), "\n".join(lines)


def named(root: str) -> dict[str, set[Path]]:
    """Per entry, the paths its names point to (``x.py`` and ``x/`` relative to the entry)."""
    out: dict[str, set[Path]] = {}
    for package, text in entries(root):
        base = ROOTS[root] / package
        head, *rest = text.split(None, 1)
        paths = out.setdefault(package, set())
        if package:
            paths.add(ROOTS[root] / package)
            text = rest[0] if rest else ""
        for name in PY_NAME.findall(text):
            paths.add(base / name)
        for name in PACKAGE_NAME.findall(text):
            paths.add(base / name.rstrip("/"))
    return out


def modules(root: str) -> list[Path]:
    return sorted(p for p in ROOTS[root].rglob("*.py") if "__pycache__" not in p.parts)


# ------------------------------------------------------------------------- the picture
@pytest.mark.parametrize("root", ROOTS)
def test_every_name_in_the_picture_exists(root):
    missing = [p.relative_to(REPO).as_posix() for paths in named(root).values() for p in paths
               if not p.exists()]
    assert not missing, f"docs/architecture.md names what is not there: {missing}"


@pytest.mark.parametrize("root", ROOTS)
def test_every_module_and_package_is_in_the_picture(root):
    names = set().union(*named(root).values())
    absent = []
    for path in modules(root):
        if path.name == "__init__.py":
            if path.parent != ROOTS[root] and path.parent not in names:
                absent.append(path.parent.relative_to(REPO).as_posix() + "/")
        elif path not in names:
            absent.append(path.relative_to(REPO).as_posix())
    assert not absent, f"not in docs/architecture.md's picture: {absent}"


def test_a_package_s_modules_are_named_on_its_own_lines():
    # batch's modules under batch/, not under another entry that happens to share a name
    for root in ROOTS:
        for package, paths in named(root).items():
            base = ROOTS[root] / package
            assert all(p == base or base in p.parents or not package for p in paths), package


# ------------------------------------------------------------------------- the imports
def unit_of(module: str) -> str | None:
    """The package or top-level module a dotted name belongs to (``link``), None outside."""
    parts = module.split(".")
    if parts[0] != "eelhost":
        return None
    return parts[1] if len(parts) > 1 else ""


@functools.cache
def imports(root: str) -> list[tuple[str, str, int]]:
    """(importing module, imported module, line) for every import of the tree, also the ones
    inside functions and ``TYPE_CHECKING`` blocks."""
    return list(_imports(root))


def _imports(root: str) -> Iterator[tuple[str, str, int]]:
    for path in modules(root):
        rel = path.relative_to(ROOTS[root]).with_suffix("")
        parts = [root, *rel.parts]
        if parts[-1] == "__init__":
            parts.pop()
        module = ".".join(parts)
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    yield module, alias.name, node.lineno
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                yield module, node.module, node.lineno
                for alias in node.names:  # from eelhost import progress
                    yield module, f"{node.module}.{alias.name}", node.lineno


def layers() -> dict[str, int]:
    out = {}
    for row in re.finditer(r"^\| (\d+) \| (.+) \|$", section("The import rules"), re.MULTILINE):
        for name in re.findall(r"`(\w+)`", row.group(2)):
            out[name] = int(row.group(1))
    return out


def exceptions() -> set[tuple[str, str]]:
    return set(re.findall(r"^- `(eelhost\.[\w.]+)` -> `(\w+)`", section("The import rules"),
                          re.MULTILINE))


def eelhost_arrows() -> Iterator[tuple[str, str, str, str]]:
    """(from unit, to unit, importing module, where) between different units of eelhost."""
    units = set(layers())
    for module, target, line in imports("eelhost"):
        src, dst = unit_of(module), unit_of(target)
        if dst is None or dst == "" or src == dst:
            continue
        if dst not in units and dst not in {p.stem for p in ROOTS["eelhost"].iterdir()}:
            continue  # ``from eelhost.x import name``: the name, not a module
        yield src or "", dst, module, f"{module}:{line}"


def test_the_layers_name_every_package_and_top_level_module_once():
    found = {p.stem if p.suffix == ".py" else p.name for p in ROOTS["eelhost"].iterdir()
             if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").exists()}
    assert set(layers()) == found


def test_eelhost_imports_only_from_layers_below_except_the_arrows_the_page_names():
    rank, allowed = layers(), exceptions()
    wrong = sorted({where + f" ({src} -> {dst})" for src, dst, module, where in eelhost_arrows()
                    if rank[dst] >= rank[src] and (module, dst) not in allowed})
    assert not wrong, f"imports against docs/architecture.md's layers: {wrong}"


def test_the_arrows_the_page_excuses_are_still_there():
    arrows = {(module, dst) for _src, dst, module, _where in eelhost_arrows()}
    assert exceptions() <= arrows, "an excused arrow is gone: take it out of the page"


def test_there_is_no_import_circle_between_eelhost_packages_but_the_excused_arrow():
    allowed = exceptions()
    graph: dict[str, set[str]] = {}
    for src, dst, module, _where in eelhost_arrows():
        if (module, dst) not in allowed:
            graph.setdefault(src, set()).add(dst)
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:  # depth first; 1 = on the path, 2 = done
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                pytest.fail("import circle: " + " -> ".join([*path[path.index(nxt):], nxt]))
            if nxt not in state:
                visit(nxt, [*path, nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])


def test_field_does_not_import_web():
    assert not [w for s, d, _m, w in eelhost_arrows() if s == "field" and d == "web"]


def test_eelsim_imports_nothing_of_eelhost():
    wrong = [f"{m}:{line}" for m, target, line in imports("eelsim")
             if target.split(".")[0] == "eelhost"]
    assert not wrong


def test_only_the_bench_commands_import_the_benchmarks():
    rule = section("The import rules")
    sentence = rule[rule.index("Only these modules import `benchmarks`"):].split(";")[0]
    allowed = {f"eelhost.{name}" for name in re.findall(r"`([\w.]+)`", sentence)} - {
        "eelhost.benchmarks"}
    importers = {module for module, target, _line in imports("eelhost")
                 if target.startswith("eelhost.benchmarks")
                 and not module.startswith("eelhost.benchmarks")}
    assert importers <= allowed, importers - allowed


def test_the_page_s_reading_finds_what_it_should():
    # the parser itself: a wrong reading would make the tests above pass on nothing
    assert ROOTS["eelsim"] / "batch" / "kernels" in named("eelsim")["batch"]
    assert ROOTS["eelhost"] / "link" / "maintenance.py" in named("eelhost")["link"]
    assert ROOTS["eelhost"] / "cli.py" in named("eelhost")[""]
    assert layers()["errors"] == 1 and layers()["commands"] > layers()["field"]
    assert ("eelhost.link.sim_transport", "xil") in exceptions()
    assert any(d == "web" for s, d, _m, _w in eelhost_arrows() if s == "commands")
