"""The frame's stages import each other in one direction only.

The data flows scene → prepared → fragments → visibility → shading → resolve → pipeline →
render; a stage may use an earlier stage but never a later one, directly or through other
modules. The arrows are the import statements of every module (module level, inside functions
and under ``TYPE_CHECKING`` alike, absolute or relative), read with :mod:`ast` by
``tools/architecture.py``; ``tests/test_import_graph.py`` checks that they form no circle and
that the renderer's rooms import only downward.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
STAGES = [
    "blinn_phong.geometry.raster",
    "blinn_phong.frame.prepared",
    "blinn_phong.frame.visibility",
    "blinn_phong.frame.shading",
    "blinn_phong.frame.resolve",
    "blinn_phong.frame.pipeline",
    "blinn_phong.frame.render",
]


def _graph() -> dict[str, set[str]]:
    spec = importlib.util.spec_from_file_location("architecture", REPO / "tools" / "architecture.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module.graph()


def reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    """Every module ``start`` imports, directly or through others."""
    seen: set[str] = set()
    todo = [start]
    while todo:
        for m in graph[todo.pop()] - seen:
            seen.add(m)
            todo.append(m)
    return seen


def test_every_stage_is_a_module() -> None:
    graph = _graph()
    assert set(STAGES) <= set(graph)


def test_no_stage_reaches_a_later_stage() -> None:
    graph = _graph()
    for i, stage in enumerate(STAGES):
        later = set(STAGES[i + 1 :]) & reachable(graph, stage)
        assert not later, f"{stage} imports (directly or not) the later stage(s) {sorted(later)}"

