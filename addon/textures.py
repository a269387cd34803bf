"""Image Texture nodes feeding a Principled BSDF → ``blinn_phong.model.texture.Texture`` (thin adapter).

Recognised: an Image Texture node whose **Color** output is linked (directly) to the Principled
BSDF's **Base Color** and/or whose **Alpha** output is linked to its **Alpha**, with its Vector
input unlinked (the active UV layer) or linked from a UV Map node (that node's layer).
Interpolation Closest/Linear and extension Repeat/Extend/Clip map one to one; other values
(Cubic, Smart; Mirror) fall back to Linear/Repeat with a note.

Pixels (``Image.pixels``, rows bottom-up) become the project's row-0-at-top image:

* byte images: the raw stored values (``Image.pixels`` gives them /255, not colour managed), with
  the image's colour space (``sRGB`` decoded exactly; ``Non-Color``/``Linear Rec.709`` as given;
  any other space: a note, used as given) and straight alpha (``alpha_mode == 'PREMUL'``:
  premultiplied; ``'NONE'``: alpha 1; ``'CHANNEL_PACKED'``: colour and alpha independent);
* float images: Blender already converted them to scene-linear premultiplied on load.

The texture gives what its linked outputs give in Cycles (:func:`texture_from_pixels`): Color and
Alpha → the straight colour and the texel alpha; Color only (Base Color) → the associated
(premultiplied) colour with the alpha ignored (``Texture(use_alpha=False)``: a transparent texel,
and with Clip the outside of the image, is opaque black, as Cycles renders it); Alpha only → white
with the texel alpha. With Base Color textured the Principled mapping is evaluated
with a white base colour (diffuse and ambient scale linearly with it); a metallic surface's
specular colour (F0 = base colour) is not textured, and emission is modulated as OpenGL's
``GL_MODULATE`` does (Blender does not): both are noted.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from blinn_phong.model.scene import Material
from blinn_phong.model.texture import Texture

if TYPE_CHECKING:  # pragma: no cover
    import bpy

__all__ = [
    "IMAGE_COLORSPACES",
    "find_image_texture",
    "mesh_uvs",
    "texture_from_node",
    "texture_from_pixels",
    "textured_material",
]

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
    from . import compat  # (bpy: this module's other functions run without it)

    image = node.image
    width, height, channels = int(image.size[0]), int(image.size[1]), int(image.channels)
    pixels = np.empty(width * height * channels, np.float32)
    image.pixels.foreach_get(pixels)
    return texture_from_pixels(
        pixels.reshape(height, width, channels)[::-1],  # Blender's rows run bottom-up
        is_float=bool(image.is_float),
        float_associated=compat.float_pixels_associated(image) if image.is_float else True,
        colorspace=str(image.colorspace_settings.name),
        alpha_mode=str(getattr(image, "alpha_mode", "STRAIGHT")),
        interpolation=str(node.interpolation),
        extension=str(node.extension),
        base=base,
        alpha=alpha,
        notes=notes,
        image_name=image.name,
        node_name=node.name,
    )


def texture_from_pixels(
    pixels: np.ndarray,
    *,
    is_float: bool,
    colorspace: str,
    alpha_mode: str,
    float_associated: bool = True,
    interpolation: str,
    extension: str,
    base: bool,
    alpha: bool,
    notes: list[str],
    image_name: str = "image",
    node_name: str = "Image Texture",
) -> Texture:
    """The :class:`Texture` an Image Texture node gives its linked outputs (no ``bpy`` needed).

    Args:
        pixels: (H, W, C) ``Image.pixels`` values, C = 1 (grey), 2 (grey, alpha), 3 or 4,
            **row 0 at the top**.
        is_float: ``Image.is_float`` (a float buffer: scene-linear, alpha associated).
        colorspace: ``Image.colorspace_settings.name`` (byte images).
        alpha_mode: ``Image.alpha_mode``: ``STRAIGHT``, ``PREMUL``, ``CHANNEL_PACKED`` or ``NONE``.
        float_associated: a float image's values are used as they are, alpha associated (Blender
            4.2–5.0); False: Cycles associates them as a straight byte image's
            (:func:`addon.compat.float_pixels_associated`).
        interpolation: the node's ``interpolation`` (``Closest``, ``Linear``, ``Cubic``, ``Smart``).
        extension: the node's ``extension`` (``REPEAT``, ``EXTEND``, ``CLIP``, ``MIRROR``).
        base: the Color output feeds the Base Color.
        alpha: the Alpha output feeds the Alpha.
        notes: conversion notes, appended to.
        image_name: the image's name, for the notes.
        node_name: the node's name, for the notes.

    What each output gives (Cycles: an image is stored with associated alpha — a byte image's
    straight values multiplied by alpha before its colour space is decoded, a float buffer as
    it is —, and the Color output is unassociated only when the Alpha output is linked):

    * Color and Alpha linked: the straight colour and the alpha (``Texture`` with straight
      alpha; the opacity is multiplied by the texel alpha).
    * Color only: the **associated** colour, ``decode(c·a)`` for a straight byte image,
      ``decode(c)`` otherwise, with the alpha ignored (``Texture(use_alpha=False)``): a
      transparent texel is black and, with Clip, so is the outside of the image — opaque.
    * Alpha only: white with the texel alpha.
    """
    height, width, channels = pixels.shape
    rgba = np.empty((height, width, 4), np.float32)
    rgba[..., :3] = pixels[..., :3] if channels >= 3 else pixels[..., :1]
    rgba[..., 3] = pixels[..., 3] if channels == 4 else (pixels[..., 1] if channels == 2 else 1.0)
    if is_float:
        space, associated = "linear", float_associated
    else:
        space = IMAGE_COLORSPACES.get(colorspace, "linear")
        if colorspace not in IMAGE_COLORSPACES:
            notes.append(
                f"{image_name}: colour space '{colorspace}' is not supported; its values are used as linear"
            )
        associated = alpha_mode == "PREMUL"
    if alpha_mode == "NONE":
        rgba[..., 3] = 1.0
    if alpha_mode == "CHANNEL_PACKED":  # colour and alpha are independent channels
        associated = False
    colour = rgba[..., :3]
    if base and (colour < 0.0).any():
        notes.append(f"{image_name}: negative pixel values are rendered as 0 (a texture holds light, >= 0)")
        np.maximum(colour, 0.0, out=colour)
    if not base:
        colour[...] = 1.0  # white encodes to white in every supported space
    elif not alpha:
        if not associated and alpha_mode == "STRAIGHT":
            colour *= rgba[..., 3:4]  # Cycles associates a straight image's stored values
        rgba[..., 3] = 1.0
    elif associated:
        a = rgba[..., 3:4]
        np.divide(colour, a, out=colour, where=a > 0.0)
        colour[np.broadcast_to(a <= 0.0, colour.shape)] = 0.0
    if space == "sRGB":
        np.clip(colour, 0.0, 1.0, out=colour)  # byte data /255: already in [0, 1]
    texture_interpolation = {"Closest": "closest", "Linear": "linear"}.get(interpolation)
    if texture_interpolation is None:
        notes.append(f"{node_name}: {interpolation} interpolation is rendered as Linear")
        texture_interpolation = "linear"
    texture_extension = {"REPEAT": "repeat", "EXTEND": "extend", "CLIP": "clip"}.get(extension)
    if texture_extension is None:
        notes.append(f"{node_name}: {extension} extension is rendered as Repeat")
        texture_extension = "repeat"
    return Texture(
        rgba,
        interpolation=texture_interpolation,
        extension=texture_extension,
        colorspace=space,
        alpha="straight",
        use_alpha=alpha,
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
    cache: dict | None = None,
) -> tuple[Material, np.ndarray | None]:
    """``material`` with the Image Texture of ``blender_material``'s Principled BSDF, and the UVs.

    Args:
        material: the converted material (``convert.material_from_blender``).
        blender_material: its Blender material.
        notes: conversion notes, appended to (and stale "linked" notes removed).
        uvs: :func:`mesh_uvs` of the mesh.
        cache: textures converted so far in this conversion (filled here): an image used by
            several objects with the same settings becomes one :class:`Texture`, not one each.

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
    key = (node.image.as_pointer(), node.interpolation, node.extension, base, alpha)
    if cache is not None and key in cache:
        texture, texture_notes = cache[key]
        notes.extend(texture_notes)
    else:
        texture_notes = []
        texture = texture_from_node(node, base, alpha, texture_notes)
        notes.extend(texture_notes)
        if cache is not None:
            cache[key] = (texture, texture_notes)
    changes: dict[str, object] = {"base_color_texture": texture}
    settings = getattr(blender_material, "blinn_phong", None)
    if base and (settings is None or settings.source != "CUSTOM"):
        from . import mapping, principled  # the same Principled values, with a white base colour

        inputs, _ = principled.principled_inputs(blender_material)
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
