"""docs/architecture.md's modules, floors and import arrows are the code's (tools/architecture.py)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _tool() -> object:
    spec = importlib.util.spec_from_file_location("architecture", REPO / "tools" / "architecture.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


def test_the_generated_part_is_current() -> None:
    assert _tool().main(["--check"]) == 0, "run: python tools/architecture.py"


def test_relative_and_function_level_imports_are_arrows(tmp_path: Path) -> None:
    tool = _tool()
    package = tmp_path / "blinn_phong"
    package.mkdir()
    (package / "__init__.py").write_text("from .a import f\n")
    (package / "a.py").write_text("def f():\n    from . import b\n")
    (package / "b.py").write_text("from blinn_phong import a\n")
    for other in tool.PACKAGES[1:]:
        (tmp_path / other).mkdir()
    arrows = tool.graph(tmp_path)
    assert arrows == {
        "blinn_phong": {"blinn_phong.a"},
        "blinn_phong.a": {"blinn_phong.b"},
        "blinn_phong.b": {"blinn_phong.a"},
    }
    assert tool.circles(arrows) == [["blinn_phong.a", "blinn_phong.b"]]
    floors = tool.floors(arrows)
    assert floors["blinn_phong.a"] == floors["blinn_phong.b"] == 0 and floors["blinn_phong"] == 1
