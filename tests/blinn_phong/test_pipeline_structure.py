"""The renderer's modules import each other in one direction only.

The data flows scene → prepared → fragments → visibility → shading → resolve; a module may
use an earlier stage but never a later one. Every ``import`` statement of every module of
``blinn_phong`` (module level, inside functions and under ``TYPE_CHECKING`` alike, absolute or
relative) is read from the source with :mod:`ast`, and the graph they form must have no cycle (a
topological order exists, Kahn 1962). ``tests/test_import_graph.py`` checks every package of the
project the same way.
"""

from __future__ import annotations

import ast
from pathlib import Path

import blinn_phong

PACKAGE = Path(blinn_phong.__file__).parent
MODULES = sorted(p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__")


def imports_of(module: str) -> set[str]:
    """The ``blinn_phong`` modules ``module`` imports anywhere in its source, absolute or relative."""
    tree = ast.parse((PACKAGE / f"{module}.py").read_text())
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1:  # ``from . import x``, ``from .x import y``
            if node.module:
                found.add(node.module.split(".")[0])
            else:
                found |= {alias.name for alias in node.names if alias.name in MODULES}
        elif isinstance(node, ast.ImportFrom) and node.module:
            if node.module == "blinn_phong":
                found |= {alias.name for alias in node.names if alias.name in MODULES}
            elif node.module.startswith("blinn_phong."):
                found.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            found |= {a.name.split(".")[1] for a in node.names if a.name.startswith("blinn_phong.")}
    found.discard(module)
    return found


def test_imports_inside_the_package_form_no_cycle() -> None:
    graph = {m: imports_of(m) for m in MODULES}
    remaining = {m: set(deps) for m, deps in graph.items()}
    order = []
    while True:  # Kahn: repeatedly remove modules that import nothing left
        ready = sorted(m for m, deps in remaining.items() if not deps)
        if not ready:
            break
        order += ready
        for m in ready:
            del remaining[m]
        for deps in remaining.values():
            deps.difference_update(ready)
    assert not remaining, f"import cycle among {sorted(remaining)}: {remaining}"


def reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    seen: set[str] = set()
    todo = [start]
    while todo:
        for m in graph[todo.pop()] - seen:
            seen.add(m)
            todo.append(m)
    return seen


def test_no_stage_reaches_a_later_stage() -> None:
    graph = {m: imports_of(m) for m in MODULES}
    stages = ["raster", "prepared", "visibility", "shading", "resolve", "pipeline", "render"]
    for i, stage in enumerate(stages):
        later = set(stages[i + 1 :]) & reachable(graph, stage)
        assert not later, f"{stage} imports (directly or not) the later stage(s) {sorted(later)}"


def test_the_former_circles_are_gone() -> None:
    # render.py ↔ frame.py and raster.py ↔ fast.py used to import each other.
    assert "render" not in imports_of("frame") and "frame" in imports_of("render")
    assert "fast" not in imports_of("raster") and "raster" in imports_of("fast")
    assert "render" not in imports_of("pipeline") and "frame" not in imports_of("pipeline")
