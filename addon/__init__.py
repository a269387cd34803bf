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
from types import ModuleType

#: Sub-modules with their own ``register()``/``unregister()``, registered in this order and
#: unregistered in reverse (the pattern of ``bpy.utils.register_submodule_factory``).
SUBMODULES: tuple[str, ...] = ("properties", "engine", "render_ui", "verify_operator", "operators", "ui")


def _submodules() -> list[ModuleType]:
    return [importlib.import_module(f".{name}", __name__) for name in SUBMODULES]


def kernel_cache_directory() -> str | None:
    """Point the compiled-kernel cache at the extension's user directory and return it.

    The project's numba kernels are cached once per user and machine
    (``compositing/_kernel_cache.py``; ``$BLINN_PHONG_KERNEL_CACHE``, else the user's cache
    directory). Installed as an extension, the cache goes to
    ``bpy.utils.extension_path_user(__package__, path="kernels")`` instead — Blender's place for an
    extension's own files, which survives Blender sessions and upgrades of the extension and goes
    away with it — by setting ``BLINN_PHONG_KERNEL_CACHE`` before any kernel module is imported
    (numba's own ``NUMBA_CACHE_DIR``, which every other add-on's numba code would follow, is left
    alone). Nothing changes when ``BLINN_PHONG_KERNEL_CACHE`` is already set, or when this package
    is not an installed extension (a plain import from the repository, a legacy add-on): then
    None is returned.
    """
    if os.environ.get("BLINN_PHONG_KERNEL_CACHE"):
        return None
    try:
        import bpy

        path = bpy.utils.extension_path_user(__package__, path="kernels", create=True)
    except (ImportError, ValueError):  # no bpy, or "The "package" does not name an extension"
        return None
    os.environ["BLINN_PHONG_KERNEL_CACHE"] = path  # read each time a kernel is decorated
    return path


def register() -> None:
    """Register every sub-module in :data:`SUBMODULES` (after :func:`kernel_cache_directory`)."""
    kernel_cache_directory()
    for module in _submodules():
        module.register()


def unregister() -> None:
    """Unregister every sub-module in :data:`SUBMODULES`, in reverse order."""
    for module in reversed(_submodules()):
        module.unregister()
