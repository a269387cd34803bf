"""The texture stage of the frame: shaded fragments modulated by their material's image texture.

Runs between :mod:`blinn_phong.shading` and the colour/resolve stage
(:mod:`blinn_phong.resolve`), on the same fragments, for both engines (the lookup is numpy;
it is a small part of the frame). For each fragment of a material with a
``base_color_texture`` (:class:`blinn_phong.texture.Texture`):

* ``uv`` is the mesh's per-vertex ``uv`` interpolated with the rasterizer's
  perspective-correct barycentrics (:func:`blinn_phong.raster.interpolate`; OpenGL 2.1 §3.5.1
  eq. 3.9), and ``T`` the filtered texel there (premultiplied), of straight colour ``t``
  and alpha ``a``;
* the colour is OpenGL's ``GL_MODULATE`` (2.1 §3.8.13, table 3.22: ``C = Cf·Ct``,
  ``A = Af·At``) applied before the colour sum (§3.9), i.e. with
  ``GL_SEPARATE_SPECULAR_COLOR`` the specular term is added after texturing:
  ``rgb = (emission + ambient + diffuse)·t + specular``. Under ``gl_compat`` the primary
  colour is clamped to [0, 1] first (per fragment), and with ``GL_SINGLE_COLOR``
  (``LightModel.separate_specular=False``) the whole clamped colour is modulated:
  ``rgb = clamp(clamp(a + d + s)·t)``.
* the opacity is ``opacity·a``; ``alpha_clip`` then makes it 1 where ``>= alpha_clip``
  and 0 elsewhere (``glAlphaFunc(GL_GEQUAL, ·)``).

The ambient and diffuse passes are modulated as the colour is; specular is not.

Limitation (gl_compat with Gouraud shading): OpenGL clamps the primary colour per vertex
and interpolates it; here it is clamped per fragment after interpolation, which is the
same wherever no vertex of the triangle has a primary colour above 1.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from blinn_phong.prepared import PreparedScene
from blinn_phong.raster import Fragments, interpolate
from blinn_phong.shading import FragmentShading
from blinn_phong.texture import straight_colour

__all__ = ["texture_fragments", "vertex_uv"]


def vertex_uv(prepared: PreparedScene) -> np.ndarray:
    """(V, 2) texture coordinates of the prepared vertices (0 for meshes without ``uv``)."""
    meshes = prepared.scene.meshes
    parts = [m.uv if m.uv is not None else np.zeros((len(m.positions), 2)) for m in meshes]
    return np.concatenate(parts) if parts else np.zeros((0, 2))


def texture_fragments(
    prepared: PreparedScene, fragments: Fragments, shaded: FragmentShading, *, gl_compat: bool = False
) -> FragmentShading:
    """``shaded`` with each textured material's texture applied (module docstring).

    Args:
        prepared: the prepared scene.
        fragments: the fragments ``shaded`` was computed for (same order).
        shaded: from :func:`blinn_phong.shading.shade_fragments` (straight colour, linear).
        gl_compat: the OpenGL 2.1 preset (clamped primary colour; the light model's colour control).

    Returns:
        ``shaded`` itself when no material is textured, else a new :class:`FragmentShading`.
    """
    scene = prepared.scene
    materials = [m for mesh in scene.meshes for m in (mesh.material, mesh.back_material or mesh.material)]
    if not any(m.textured for m in materials) or len(fragments) == 0:
        return shaded
    back = ~fragments.front_facing if scene.light_model.two_sided else np.zeros(len(fragments), bool)
    side = 2 * prepared.triangle_mesh[fragments.triangle] + back
    separate = scene.light_model.separate_specular or not gl_compat
    rgb = shaded.rgb.copy()
    ambient = shaded.ambient.copy()
    diffuse = shaded.diffuse.copy()
    alpha = np.asarray(shaded.alpha, dtype=np.float64).copy()
    uv = None
    for s in np.unique(side):
        material = materials[s]
        if not material.textured:
            continue
        here = np.flatnonzero(side == s)
        texture = material.base_color_texture
        if texture is not None:
            if uv is None:
                uv = interpolate(fragments, prepared.triangles, vertex_uv(prepared))
            texel = texture.sample(uv[here])
            colour = straight_colour(texel)
            a, d, sp = shaded.ambient[here], shaded.diffuse[here], shaded.specular[here]
            if not gl_compat:
                rgb[here] = (a + d) * colour + sp
            elif separate:
                rgb[here] = np.clip(np.clip(a + d, 0.0, 1.0) * colour + np.clip(sp, 0.0, 1.0), 0.0, 1.0)
            else:
                rgb[here] = np.clip(np.clip(a + d + sp, 0.0, 1.0) * colour, 0.0, 1.0)
            ambient[here] = a * colour
            diffuse[here] = d * colour
            if material.kay_greenberg is None:
                alpha[here] = alpha[here] * texel[:, 3]
        if material.alpha_clip is not None:
            alpha[here] = np.where(alpha[here] >= material.alpha_clip, 1.0, 0.0)
    return dataclasses.replace(shaded, rgb=rgb, ambient=ambient, diffuse=diffuse, alpha=alpha)
