"""The Porter-Duff submenu in the compositor's Add menu."""

from __future__ import annotations

import bpy

from . import node_groups

__all__ = ["NODE_MT_porter_duff", "classes", "draw_add_menu", "register", "unregister"]


class NODE_MT_porter_duff(bpy.types.Menu):  # noqa: N801 (Blender naming rule)
    """Porter-Duff compositing operators as node groups"""

    bl_idname = "NODE_MT_porter_duff"
    bl_label = "Porter-Duff"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        for names in (node_groups.ARTIST_OPERATORS, node_groups.ALPHA_OVER_MODE_OPERATORS):
            for name in names:
                props = layout.operator("node.porter_duff_add", text=node_groups.group_name(name))
                props.operator = name
            layout.separator()
        layout.operator("node.porter_duff_add_groups")


def draw_add_menu(self: bpy.types.Menu, context: bpy.types.Context) -> None:
    """Append the Porter-Duff submenu to the Add menu of the compositor (not of other node editors)."""
    space = context.space_data
    if space is not None and getattr(space, "tree_type", None) == "CompositorNodeTree":
        self.layout.menu(NODE_MT_porter_duff.bl_idname)


classes = (NODE_MT_porter_duff,)


def register() -> None:
    """Register the menu and hook it into the node editor's Add menu."""
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.NODE_MT_add.append(draw_add_menu)


def unregister() -> None:
    """Remove the Add-menu hook and the menu."""
    bpy.types.NODE_MT_add.remove(draw_add_menu)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
