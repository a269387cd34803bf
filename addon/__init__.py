"""Blender extension: Porter-Duff compositing node groups and checks against Blender's compositor.

Layout (after Blender's Cycles add-on and glTF-Blender-IO): ``operators`` and ``ui``
hold the Blender classes, ``node_groups`` builds the groups, ``compat`` holds every
difference between Blender 4.2, 4.5 and 5.0, ``factor_graph`` plans node graphs
without Blender, ``verify`` compares Blender's compositor with :mod:`compositing`.

The extension's metadata lives in ``blender_manifest.toml``. Importing this package does not
import ``bpy``: the verification CLI
(``python -m addon.verify``) runs in a plain Python and starts Blender itself.
"""

from __future__ import annotations


def register() -> None:
    """Register the operators and the Add-menu entry."""
    import bpy

    from . import operators, ui

    for cls in (*operators.classes, *ui.classes):
        bpy.utils.register_class(cls)
    bpy.types.NODE_MT_add.append(ui.draw_add_menu)


def unregister() -> None:
    """Remove everything :func:`register` added, in reverse order."""
    import bpy

    from . import operators, ui

    bpy.types.NODE_MT_add.remove(ui.draw_add_menu)
    for cls in reversed((*operators.classes, *ui.classes)):
        bpy.utils.unregister_class(cls)
