"""The project's modules import each other without a circle.

Every ``.py`` file of ``blinn_phong``, ``compositing``, ``addon``, ``benchmarks``, ``oracles`` and
``tools`` is parsed with :mod:`ast`; every ``import`` / ``from ... import`` statement in it (module
level, inside functions, under ``TYPE_CHECKING`` alike), absolute or relative (``from . import x``,
``from ..pkg.mod import y``, resolved against the importing module's package as the import system
does, PEP 328), becomes an edge from the importing module to the project module it names. The
graph must have no cycle: a failure names one cycle as a path ``a -> b -> ... -> a`` per strongly
connected component (Tarjan 1972).

Resolution of one statement (the most specific project module it names):

* ``import a.b.c`` → the longest prefix of ``a.b.c`` that is a project module;
* ``from a.b import c`` → ``a.b.c`` when that is a module (a submodule imported by name),
  otherwise ``a.b`` itself (an attribute of that module, or of a package's ``__init__``).

A package's ``__init__.py`` is the module named like the package. An edge to a package is kept:
``from blinn_phong import Fog`` inside ``blinn_phong`` runs ``blinn_phong/__init__.py``, and a
cycle through it is a real circle.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("blinn_phong", "compositing", "addon", "benchmarks", "oracles", "tools")


def module_name(path: Path) -> str:
    """``blinn_phong/frame.py`` → ``blinn_phong.frame``; ``addon/__init__.py`` → ``addon``."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def project_files() -> dict[str, Path]:
    """Every module of :data:`PACKAGES` by dotted name."""
    files: dict[str, Path] = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            files[module_name(path)] = path
    return files


def resolve_from(importer: str, is_package: bool, level: int, module: str | None) -> str:
    """The absolute module name of ``from <'.' * level><module> import ...`` in ``importer``."""
    if level == 0:
        return module or ""
    base = importer.split(".") if is_package else importer.split(".")[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def longest_module(name: str, modules: set[str]) -> str | None:
    """The longest dotted prefix of ``name`` that is a project module, if any."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        candidate = ".".join(parts[:n])
        if candidate in modules:
            return candidate
    return None


def imports_of(name: str, path: Path, modules: set[str]) -> set[str]:
    """The project modules that module ``name`` (source at ``path``) imports anywhere."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                target = longest_module(alias.name, modules)
                if target:
                    found.add(target)
        elif isinstance(node, ast.ImportFrom):
            base = resolve_from(name, is_package, node.level, node.module)
            for alias in node.names:
                target = longest_module(f"{base}.{alias.name}" if base else alias.name, modules)
                if target:
                    found.add(target)
    found.discard(name)
    return found


def import_graph() -> dict[str, set[str]]:
    files = project_files()
    modules = set(files)
    return {name: imports_of(name, path, modules) for name, path in files.items()}


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components with more than one module (iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    components: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        components.append(sorted(component))
    return components


def cycle_in(graph: dict[str, set[str]], component: list[str]) -> list[str]:
    """One cycle through ``component``'s first module, as a path that ends where it starts."""
    members = set(component)
    start = component[0]
    parent: dict[str, str] = {}
    todo = [start]
    while todo:  # breadth first: the shortest cycle through ``start``
        node = todo.pop(0)
        for child in sorted(graph[node] & members):
            if child == start:
                path = [node]
                while path[-1] != start:
                    path.append(parent[path[-1]])
                return [start, *reversed(path[:-1]), start] if node != start else [start, start]
            if child not in parent:
                parent[child] = node
                todo.append(child)
    raise AssertionError(f"no cycle through {start} in {component}")  # pragma: no cover


def test_relative_imports_are_resolved() -> None:
    # ``compositing/gl_blend.py`` imports its package's modules relatively only; the graph
    # must see those edges, or circles among relative imports would pass unseen.
    graph = import_graph()
    assert "compositing.factors" in graph["compositing.gl_blend"]
    assert resolve_from("addon.convert", False, 1, "textures") == "addon.textures"
    assert resolve_from("addon", True, 1, None) == "addon"
    assert resolve_from("a.b.c", False, 2, "d") == "a.d"


def test_the_project_has_no_import_cycle() -> None:
    graph = import_graph()
    cycles = [" -> ".join(cycle_in(graph, c)) for c in strongly_connected(graph)]
    assert not cycles, "import cycle(s) among the project's modules:\n" + "\n".join(cycles)
