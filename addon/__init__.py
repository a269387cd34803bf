"""Blender extension: the Blinn-Phong render engine and Porter-Duff compositor node groups.

Layout (after Blender's Cycles add-on and glTF-Blender-IO): ``properties``, ``engine`` and
``render_ui`` hold the render engine; ``operators`` and ``ui`` the Porter-Duff node groups
(built by ``node_groups``); ``compat`` holds every difference between Blender 4.2, 4.5 and
5.0; ``mapping`` and ``factor_graph`` are pure logic without ``bpy``; ``verify`` compares
Blender's compositor with :mod:`compositing`.

The extension's metadata lives in ``blender_manifest.toml``. Importing this package does not
import ``bpy``: the verification CLI (``python -m addon.verify``) runs in a plain Python and
starts Blender itself.
"""

from __future__ import annotations

import importlib
from types import ModuleType

#: Sub-modules with their own ``register()``/``unregister()``, registered in this order and
#: unregistered in reverse (the pattern of ``bpy.utils.register_submodule_factory``).
SUBMODULES: tuple[str, ...] = ("properties", "engine", "render_ui", "verify_operator", "operators", "ui")


def _submodules() -> list[ModuleType]:
    return [importlib.import_module(f".{name}", __name__) for name in SUBMODULES]


def register() -> None:
    """Register every sub-module in :data:`SUBMODULES`."""
    for module in _submodules():
        module.register()


def unregister() -> None:
    """Unregister every sub-module in :data:`SUBMODULES`, in reverse order."""
    for module in reversed(_submodules()):
        module.unregister()
