"""Operators: add the Porter-Duff node groups to the current file, or one group node to the editor."""

import bpy

from . import node_groups

__all__ = ["NODE_OT_porter_duff_add", "NODE_OT_porter_duff_add_groups", "classes", "register", "unregister"]


class NODE_OT_porter_duff_add_groups(bpy.types.Operator):  # noqa: N801 (Blender naming rule)
    """Add every Porter-Duff node group (12 operators, plus, disjoint and conjoint over) to the file"""

    bl_idname = "node.porter_duff_add_groups"
    bl_label = "Add Porter-Duff Node Groups"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012

    def execute(self, context: bpy.types.Context) -> set[str]:
        names = (*node_groups.ARTIST_OPERATORS, *node_groups.ALPHA_OVER_MODE_OPERATORS)
        for operator in names:
            node_groups.ensure_group(operator)
        self.report({"INFO"}, f"{len(names)} Porter-Duff node groups ready")
        return {"FINISHED"}


# Property annotations stay real objects (no `from __future__ import annotations`): Blender reads them.
class NODE_OT_porter_duff_add(bpy.types.Operator):  # noqa: N801 (Blender naming rule)
    """Add a Porter-Duff group node to the active compositor tree"""

    bl_idname = "node.porter_duff_add"
    bl_label = "Add Porter-Duff Node"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012

    operator: bpy.props.StringProperty(name="Operator", description="Operator name, e.g. src_atop")

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        space = context.space_data
        return (
            space is not None
            and space.type == "NODE_EDITOR"
            and space.tree_type == "CompositorNodeTree"
            and space.edit_tree is not None
        )

    def execute(self, context: bpy.types.Context) -> set[str]:
        if self.operator not in (*node_groups.ARTIST_OPERATORS, *node_groups.ALPHA_OVER_MODE_OPERATORS):
            self.report({"ERROR"}, f"Unknown Porter-Duff operator {self.operator!r}")
            return {"CANCELLED"}
        tree = context.space_data.edit_tree
        for node in tree.nodes:
            node.select = False
        node = tree.nodes.new("CompositorNodeGroup")
        node.node_tree = node_groups.ensure_group(self.operator)
        node.location = context.space_data.cursor_location
        node.select = True
        tree.nodes.active = node
        return {"FINISHED"}


classes = (NODE_OT_porter_duff_add_groups, NODE_OT_porter_duff_add)


def register() -> None:
    """Register the operators."""
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister() -> None:
    """Unregister the operators, in reverse order."""
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
