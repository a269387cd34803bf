"""Image Texture nodes feeding a Principled BSDF → ``blinn_phong.texture.Texture`` (thin adapter).

Recognised: an Image Texture node whose **Color** output is linked (directly) to the Principled
BSDF's **Base Color** and/or whose **Alpha** output is linked to its **Alpha**, with its Vector
input unlinked (the active UV layer) or linked from a UV Map node (that node's layer).
Interpolation Closest/Linear and extension Repeat/Extend/Clip map one to one; other values
(Cubic, Smart; Mirror) fall back to Linear/Repeat with a note.

Pixels (``Image.pixels``, rows bottom-up) become the project's row-0-at-top image:

* byte images: the raw stored values (``Image.pixels`` gives them /255, not colour managed), with
  the image's colour space (``sRGB`` decoded exactly; ``Non-Color``/``Linear Rec.709`` as given;
  any other space: a note, used as given) and straight alpha (``alpha_mode == 'PREMUL'``:
  premultiplied; ``'NONE'``/``'CHANNEL_PACKED'``: alpha ignored);
* float images: Blender already converted them to scene-linear premultiplied on load.

The texture modulates what it feeds: Base Color only → the texels' alpha is set to 1; Alpha only
→ the texels' colour is set to white. With Base Color textured the Principled mapping is evaluated
with a white base colour (diffuse and ambient scale linearly with it); a metallic surface's
specular colour (F0 = base colour) is not textured, and emission is modulated as OpenGL's
``GL_MODULATE`` does (Blender does not): both are noted.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from blinn_phong.scene import Material
from blinn_phong.texture import Texture

if TYPE_CHECKING:  # pragma: no cover
    import bpy

__all__ = ["IMAGE_COLORSPACES", "find_image_texture", "mesh_uvs", "texture_from_node", "textured_material"]

#: Blender colour-space names → ``Texture.colorspace``.
IMAGE_COLORSPACES = {
    "sRGB": "sRGB",
    "Non-Color": "Non-Color",
    "Linear Rec.709": "linear",
    "Linear": "linear",
    "Raw": "Non-Color",
}


def find_image_texture(principled: bpy.types.Node) -> tuple[bpy.types.Node | None, bool, bool, str | None]:
    """``(image node, feeds Base Color, feeds Alpha, UV layer name or None for the active one)``."""
    found = None
    base = alpha = False
    for socket_name, output_name in (("Base Color", "Color"), ("Alpha", "Alpha")):
        socket = principled.inputs.get(socket_name)
        if socket is None or not socket.is_linked:
            continue
        link = socket.links[0]
        node = link.from_node
        if node.type != "TEX_IMAGE" or node.image is None or link.from_socket.name != output_name:
            continue
        if found is not None and node != found:
            continue  # two different images: the Base Color one wins
        found = node
        base = base or socket_name == "Base Color"
        alpha = alpha or socket_name == "Alpha"
    layer = None
    if found is not None:
        vector = found.inputs.get("Vector")
        if vector is not None and vector.is_linked:
            source = vector.links[0].from_node
            layer = source.uv_map if source.type == "UVMAP" and source.uv_map else None
    return found, base, alpha, layer


def texture_from_node(node: bpy.types.Node, base: bool, alpha: bool, notes: list[str]) -> Texture:
    """The :class:`Texture` of an Image Texture node (module docstring for the conversions)."""
    image = node.image
    width, height = int(image.size[0]), int(image.size[1])
    pixels = np.empty(width * height * int(image.channels), np.float32)
    image.pixels.foreach_get(pixels)
    pixels = pixels.reshape(height, width, int(image.channels))[::-1]
    rgba = np.ones((height, width, 4), np.float64)
    rgba[..., : min(4, pixels.shape[2])] = pixels[..., :4]
    if pixels.shape[2] in (1, 2):  # grey (+ alpha)
        rgba[..., :3] = pixels[..., :1]
        rgba[..., 3] = pixels[..., 1] if pixels.shape[2] == 2 else 1.0
    mode = str(getattr(image, "alpha_mode", "STRAIGHT"))
    if image.is_float:
        colorspace, premultiplied = "linear", True
    else:
        name = image.colorspace_settings.name
        colorspace = IMAGE_COLORSPACES.get(name, "linear")
        if name not in IMAGE_COLORSPACES:
            notes.append(
                f"{image.name}: colour space '{name}' is not supported; its values are used as linear"
            )
        premultiplied = mode == "PREMUL"
    if mode in ("NONE", "CHANNEL_PACKED"):
        rgba[..., 3] = 1.0
    if not premultiplied:
        straight = rgba[..., :3]
    else:
        a = rgba[..., 3:4]
        straight = np.where(a > 0, rgba[..., :3] / np.where(a > 0, a, 1.0), 0.0)
    if colorspace == "sRGB":
        straight = np.clip(straight, 0.0, 1.0)  # byte data /255: already in [0, 1]
    if not alpha:
        rgba[..., 3] = 1.0
    if not base:
        straight = np.ones_like(straight)  # white encodes to white in every supported space
    image_in = np.concatenate([straight, rgba[..., 3:4]], axis=-1)
    interpolation = {"Closest": "closest", "Linear": "linear"}.get(node.interpolation)
    if interpolation is None:
        notes.append(f"{node.name}: {node.interpolation} interpolation is rendered as Linear")
        interpolation = "linear"
    extension = {"REPEAT": "repeat", "EXTEND": "extend", "CLIP": "clip"}.get(node.extension)
    if extension is None:
        notes.append(f"{node.name}: {node.extension} extension is rendered as Repeat")
        extension = "repeat"
    if (image_in < 0.0).any():
        notes.append(f"{image.name}: negative pixel values are rendered as 0 (a texture holds light, >= 0)")
    return Texture(
        np.clip(image_in, 0.0, None),
        interpolation=interpolation,
        extension=extension,
        colorspace=colorspace,
        alpha="straight",
    )


def mesh_uvs(mesh: bpy.types.Mesh) -> dict[str, np.ndarray]:
    """(L, 2) per-corner UVs of every UV layer by name, and of the active one under ``""``."""
    out: dict[str, np.ndarray] = {}
    for uv_layer in mesh.uv_layers:
        uv = np.empty(len(mesh.loops) * 2, np.float32)
        uv_layer.data.foreach_get("uv", uv)
        out[uv_layer.name] = uv.reshape(-1, 2).astype(np.float64)
        if uv_layer.active:
            out[""] = out[uv_layer.name]
    return out


def textured_material(
    material: Material,
    blender_material: bpy.types.Material | None,
    notes: list[str],
    uvs: dict[str, np.ndarray],
) -> tuple[Material, np.ndarray | None]:
    """``material`` with the Image Texture of ``blender_material``'s Principled BSDF, and the UVs.

    Args:
        material: the converted material (``convert.material_from_blender``).
        blender_material: its Blender material.
        notes: conversion notes, appended to (and stale "linked" notes removed).
        uvs: :func:`mesh_uvs` of the mesh.

    Returns ``(material, uv)``: unchanged and None when no Image Texture feeds the Principled
    BSDF, or when the mesh lacks the UV layer (with a note).
    """
    tree = getattr(blender_material, "node_tree", None)
    if tree is None:
        return material, None
    principled = next((n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
    if principled is None:
        return material, None
    node, base, alpha, layer = find_image_texture(principled)
    if node is None:
        return material, None
    uv = uvs.get(layer or "")
    if uv is None:
        notes.append(
            f"{blender_material.name}: the mesh has no UV layer {layer or '(active)'!r}; texture ignored"
        )
        return material, None
    texture = texture_from_node(node, base, alpha, notes)
    changes: dict[str, object] = {"base_color_texture": texture}
    settings = getattr(blender_material, "blinn_phong", None)
    if base and (settings is None or settings.source != "CUSTOM"):
        from . import convert, mapping  # the same Principled values, with a white base colour

        inputs, _ = convert.principled_inputs(blender_material)
        inputs["base_color"] = (1.0, 1.0, 1.0)
        values = mapping.blinn_phong_from_principled(**inputs)
        changes.update(ambient=values["ambient"], diffuse=values["diffuse"], specular=values["specular"])
        if float(inputs.get("metallic", 0.0)) > 0.0:
            notes.append(
                f"{blender_material.name}: a textured metallic Base Color does not tint the specular"
            )
    if alpha:
        changes["opacity"] = 1.0  # the linked socket's unlinked value does not apply
    linked = [s for s in ("Base Color", "Alpha") if (s == "Base Color" and base) or (s == "Alpha" and alpha)]
    for s in linked:  # principled_inputs noted these as "linked; unlinked value used": no longer true
        stale = f"{blender_material.name}: '{s}' is linked; its unlinked value is used"
        while stale in notes:
            notes.remove(stale)
    if material.emission != (0.0, 0.0, 0.0) and base:
        notes.append(
            f"{blender_material.name}: the Base Color texture also modulates the emission (GL_MODULATE)"
        )
    return dataclasses.replace(material, **changes), uv
