"""The project's modules import each other without a circle, and docs/architecture.md's map of
them is the code's (both from ``tools/architecture.py``).

Every ``.py`` file of ``blinn_phong``, ``compositing``, ``addon``, ``benchmarks``, ``oracles`` and
``tools`` is parsed with :mod:`ast`; every import statement in it (module level, inside functions,
under ``TYPE_CHECKING`` alike), absolute or relative (resolved against the importing module's
package as the import system does, PEP 328), is an arrow to the project module it names
(``from a.b import c``: ``a.b.c`` when that is a module, else ``a.b``). A circle is a strongly
connected component of more than one module (Tarjan 1972); a failure names one cycle of each as
a path ``a -> b -> ... -> a``.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _tool() -> object:
    spec = importlib.util.spec_from_file_location("architecture", REPO / "tools" / "architecture.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


def test_the_project_has_no_import_cycle() -> None:
    tool = _tool()
    arrows = tool.graph()
    cycles = [" -> ".join(tool.cycle_path(arrows, c)) for c in tool.circles(arrows)]
    assert not cycles, "import cycle(s) among the project's modules:\n" + "\n".join(cycles)


def test_the_renderers_rooms_import_only_downward() -> None:
    tool = _tool()
    climbing = tool.upward_arrows(tool.graph())
    listed = "\n".join(f"{a} -> {b}" for a, b in climbing)
    assert not climbing, "imports from a room to a room above it (tools/architecture.py ROOMS):\n" + listed


def test_a_climbing_import_is_found(tmp_path: Path) -> None:
    tool = _tool()
    package = tmp_path / "blinn_phong"
    for room in ("model", "frame"):
        (package / room).mkdir(parents=True)
        (package / room / "__init__.py").write_text("")
    (package / "__init__.py").write_text("from blinn_phong.frame.run import go\n")
    (package / "_helper.py").write_text("")
    run = "from blinn_phong.model import data\nfrom blinn_phong import _helper\n"
    (package / "frame" / "run.py").write_text(run)
    (package / "model" / "data.py").write_text("def f():\n    from ..frame import run\n")
    for other in tool.PACKAGES[1:]:
        (tmp_path / other).mkdir()
    assert tool.upward_arrows(tool.graph(tmp_path)) == [("blinn_phong.model.data", "blinn_phong.frame.run")]


def test_relative_and_function_level_imports_are_arrows(tmp_path: Path) -> None:
    tool = _tool()
    # ``compositing/gl_blend.py`` imports its package's modules relatively only
    assert "compositing.factors" in tool.graph()["compositing.gl_blend"]
    package = tmp_path / "blinn_phong"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("from .a import f\n")
    (package / "a.py").write_text("def f():\n    from . import b\n")
    (package / "b.py").write_text("from blinn_phong import a\n")
    (package / "sub" / "__init__.py").write_text("")
    (package / "sub" / "c.py").write_text("from ..a import f\nfrom .. import b\n")
    for other in tool.PACKAGES[1:]:
        (tmp_path / other).mkdir()
    arrows = tool.graph(tmp_path)
    a, b, c = "blinn_phong.a", "blinn_phong.b", "blinn_phong.sub.c"
    assert arrows == {"blinn_phong": {a}, a: {b}, b: {a}, "blinn_phong.sub": set(), c: {a, b}}
    assert tool.circles(arrows) == [[a, b]]
    assert tool.cycle_path(arrows, [a, b]) == [a, b, a]
    floors = tool.floors(arrows)
    assert floors[a] == floors[b] == 0 and floors["blinn_phong"] == floors[c] == 1


def test_the_architecture_page_is_current() -> None:
    assert _tool().main(["--check"]) == 0, "run: python tools/architecture.py"
