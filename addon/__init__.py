"""Blender extension: the Blinn-Phong render engine and Porter-Duff compositor node groups.

Layout (after Blender's Cycles add-on and glTF-Blender-IO): ``properties``, ``engine`` and
``render_ui`` hold the render engine, with its settings declared once in ``options``;
``operators`` and ``ui`` the Porter-Duff node groups (built by ``node_groups``); ``compat`` holds
every difference between Blender 4.2, 4.5, 5.0 and 5.2; ``options``, ``pipeline``, ``mapping`` and
``factor_graph`` are pure logic without ``bpy``; ``verify`` compares
Blender's compositor with :mod:`compositing`.

The extension's metadata lives in ``blender_manifest.toml``. Importing this package does not
import ``bpy``: the verification CLI (``python -m addon.verify``) runs in a plain Python and
starts Blender itself.
"""

from __future__ import annotations

import importlib
import os
import sys
from types import ModuleType

#: Sub-modules with their own ``register()``/``unregister()``, registered in this order and
#: unregistered in reverse (the pattern of ``bpy.utils.register_submodule_factory``).
SUBMODULES: tuple[str, ...] = ("properties", "engine", "render_ui", "verify_operator", "operators", "ui")


def _submodules() -> list[ModuleType]:
    return [importlib.import_module(f".{name}", __name__) for name in SUBMODULES]


def numba_cache_directory() -> str | None:
    """Point numba's on-disk kernel cache at the extension's user directory and return it.

    numba caches compiled kernels next to their source file by default, so every install location
    (and a read-only System repository) compiles again. Installed as an extension, the cache goes to
    ``bpy.utils.extension_path_user(__package__, path="numba_cache")``, which survives Blender
    sessions and upgrades of the extension: the kernels compile once per machine. Nothing changes
    when ``NUMBA_CACHE_DIR`` is already set, or when this package is not an installed extension
    (a plain import from the repository, a legacy add-on): then None is returned.
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    try:
        import bpy

        path = bpy.utils.extension_path_user(__package__, path="numba_cache", create=True)
    except (ImportError, ValueError):  # no bpy, or "The "package" does not name an extension"
        return None
    os.environ["NUMBA_CACHE_DIR"] = path  # read when numba is first imported
    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba already imported (by another add-on): its config is live
        config.CACHE_DIR = path
    return path


def register() -> None:
    """Register every sub-module in :data:`SUBMODULES` (after :func:`numba_cache_directory`)."""
    numba_cache_directory()
    for module in _submodules():
        module.register()


def unregister() -> None:
    """Unregister every sub-module in :data:`SUBMODULES`, in reverse order."""
    for module in reversed(_submodules()):
        module.unregister()
