"""The Principled BSDF's unlinked input values, read out of a Blender material.

Shared by ``addon/convert.py`` (a material's Blinn-Phong coefficients) and ``addon/textures.py``
(the same coefficients with a white base colour under an image texture); both import it, it
imports neither.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import bpy

__all__ = ["clamp_to_socket_range", "principled_inputs"]

_PRINCIPLED_SOCKETS = {
    "base_color": "Base Color",
    "metallic": "Metallic",
    "roughness": "Roughness",
    "ior": "IOR",
    "specular_ior_level": "Specular IOR Level",
    "emission_color": "Emission Color",
    "emission_strength": "Emission Strength",
    "alpha": "Alpha",
}


def _surface_principled(tree: bpy.types.NodeTree, name: str, notes: list[str]) -> bpy.types.Node | None:
    """The Principled BSDF that feeds the active Material Output's Surface, else the first one."""
    outputs = [n for n in tree.nodes if n.type == "OUTPUT_MATERIAL"]
    output = next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)
    surface = output.inputs.get("Surface") if output is not None else None
    if surface is not None and surface.is_linked:
        source = surface.links[0].from_node
        if source.type == "BSDF_PRINCIPLED":
            return source
        notes.append(f"{name}: the surface is a {source.bl_label} node; the first Principled BSDF is used")
    return next((n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"), None)


def principled_inputs(material: bpy.types.Material | None) -> tuple[dict[str, object], list[str]]:
    """Unlinked input values of the material's Principled BSDF (the one feeding the active Material
    Output), as keyword arguments of ``mapping.blinn_phong_from_principled``; plus notes on what
    was ignored.

    Without a node tree or a Principled BSDF node, the viewport display values
    (``diffuse_color``, ``metallic``, ``roughness``) are used.
    """
    notes: list[str] = []
    if material is None:
        return {"base_color": (0.8, 0.8, 0.8)}, notes
    tree = material.node_tree
    node = None if tree is None else _surface_principled(tree, material.name, notes)
    if node is None:
        return {
            "base_color": tuple(material.diffuse_color[:3]),
            "metallic": float(material.metallic),
            "roughness": float(material.roughness),
            "alpha": float(material.diffuse_color[3]),
        }, notes
    values: dict[str, object] = {}
    for key, name in _PRINCIPLED_SOCKETS.items():
        socket = node.inputs.get(name)
        if socket is None:
            continue
        if socket.is_linked:
            notes.append(f"{material.name}: '{name}' is linked; its unlinked value is used")
        value = socket.default_value
        if key.endswith("color"):
            values[key] = tuple(float(v) for v in value[:3])
        else:
            values[key] = clamp_to_socket_range(socket, float(value), material.name, notes)
    return values, notes


def clamp_to_socket_range(
    socket: bpy.types.NodeSocket, value: float, material: str, notes: list[str]
) -> float:
    """``value`` limited to the range the socket declares (``hard_min``/``hard_max`` of its
    ``default_value``), with a note naming the material when it was outside.

    Blender stores values outside a socket's declared range when they are set from Python
    (Roughness 1.2, Alpha 1.5); its sockets' declared ranges are the inputs the Principled BSDF is
    defined for, so such values are rendered as the nearest end of the range, and said so.
    IOR declares no range (any float): it is checked by ``mapping.blinn_phong_from_principled``.
    """
    prop = socket.bl_rna.properties["default_value"]
    low, high = float(getattr(prop, "hard_min", -math.inf)), float(getattr(prop, "hard_max", math.inf))
    if math.isfinite(value) and not low <= value <= high:
        clamped = min(max(value, low), high)
        notes.append(
            f"{material}: '{socket.name}' {value:g} is outside Blender's range [{low:g}, {high:g}]; "
            f"rendered as {clamped:g}"
        )
        return clamped
    return value
