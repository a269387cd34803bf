"""The texture stage of the frame: shaded fragments modulated by their material's image texture.

Runs between :mod:`blinn_phong.frame.shading` and the colour/resolve stage
(:mod:`blinn_phong.frame.resolve`), on the same fragments: ``engine="numpy"`` is the reference below,
``"numba"`` a compiled twin doing the same per fragment in one parallel pass (uv, lookup,
modulation; equal to the reference to rounding, tests/blinn_phong/test_texture.py). For each
fragment of a material with a ``base_color_texture`` (:class:`blinn_phong.model.texture.Texture`):

* ``uv`` is the mesh's per-vertex ``uv`` interpolated with the rasterizer's
  perspective-correct barycentrics (:func:`blinn_phong.geometry.raster.interpolate`; OpenGL 2.1 §3.5.1
  eq. 3.9), and ``T`` the filtered texel there (premultiplied), of straight colour ``t``
  and alpha ``a`` (a texture with ``use_alpha=False`` is an RGB texture: ``a = 1`` and ``t``
  the filtered premultiplied colour, so its texels never change the opacity — GL's
  ``GL_MODULATE`` on an ``RGB`` texture, table 3.22: ``A = Af``);
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
import functools
import weakref

import numpy as np

from blinn_phong._numba import use_compiled
from blinn_phong.frame.prepared import PreparedScene
from blinn_phong.frame.shading import FragmentShading
from blinn_phong.geometry.raster import Fragments, interpolate
from blinn_phong.model.texture import EXTENSIONS, INTERPOLATIONS, UV_LIMIT, straight_colour

__all__ = ["texture_fragments", "vertex_uv"]


def vertex_uv(prepared: PreparedScene) -> np.ndarray:
    """(V, 2) texture coordinates of the prepared vertices (0 for meshes without ``uv``)."""
    meshes = prepared.scene.meshes
    parts = [m.uv if m.uv is not None else np.zeros((len(m.positions), 2)) for m in meshes]
    return np.concatenate(parts) if parts else np.zeros((0, 2))


def texture_fragments(
    prepared: PreparedScene,
    fragments: Fragments,
    shaded: FragmentShading,
    *,
    gl_compat: bool = False,
    engine: str = "numpy",
) -> FragmentShading:
    """``shaded`` with each textured material's texture applied (module docstring).

    Args:
        prepared: the prepared scene.
        fragments: the fragments ``shaded`` was computed for (same order).
        shaded: from :func:`blinn_phong.frame.shading.shade_fragments` (straight colour, linear).
        gl_compat: the OpenGL 2.1 preset (clamped primary colour; the light model's colour control).
        engine: ``"numpy"`` (reference) or ``"numba"``/``"auto"`` (compiled, when numba imports).

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
    if use_compiled(engine):
        return _texture_compiled(prepared, fragments, shaded, side, materials, gl_compat, separate)
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
            if uv is None:  # ±UV_LIMIT: an interpolation overflowing to ±inf is its limit
                uv = interpolate(fragments, prepared.triangles, vertex_uv(prepared))
                np.clip(uv, -UV_LIMIT, UV_LIMIT, out=uv)
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


def _texture_compiled(
    prepared: PreparedScene,
    fragments: Fragments,
    shaded: FragmentShading,
    side: np.ndarray,
    materials: list,
    gl_compat: bool,
    separate: bool,
) -> FragmentShading:
    """The compiled twin of the reference loop of :func:`texture_fragments`."""
    tex_of_side, clip_of_side, kg_of_side, pixels, offsets, shape, modes = _packed(prepared, materials)
    mode = 0 if not gl_compat else (1 if separate else 2)
    rgb, ambient, diffuse, alpha = _kernel()(
        fragments.triangle,
        fragments.bary,
        prepared.triangles,
        vertex_uv(prepared),
        side.astype(np.int64),
        tex_of_side,
        clip_of_side,
        kg_of_side,
        pixels,
        offsets,
        shape,
        modes,
        np.ascontiguousarray(shaded.ambient, dtype=np.float64),
        np.ascontiguousarray(shaded.diffuse, dtype=np.float64),
        np.ascontiguousarray(shaded.specular, dtype=np.float64),
        np.ascontiguousarray(shaded.rgb, dtype=np.float64),
        np.asarray(shaded.alpha, dtype=np.float64),
        mode,
        UV_LIMIT,
    )
    return dataclasses.replace(shaded, rgb=rgb, ambient=ambient, diffuse=diffuse, alpha=alpha)


#: The textures of a prepared scene packed for the kernel, kept while the scene lives (the
#: frame calls the texture stage once per band of rows: the packing is done once).
_PACKED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _packed(prepared: PreparedScene, materials: list) -> tuple[np.ndarray, ...]:
    """Per side: texture index, alpha clip, Kay–Greenberg flag; all texels, offsets, sizes, modes.

    One texture's texels are its stored image itself (no copy); several are concatenated once
    per prepared scene.
    """
    cached = _PACKED.get(prepared)
    if cached is not None:
        return cached
    textures: list = []
    tex_of_side = np.full(len(materials), -1, np.int64)
    clip_of_side = np.full(len(materials), -1.0)
    kg_of_side = np.array([m.kay_greenberg is not None for m in materials], dtype=np.bool_)
    for s, m in enumerate(materials):
        if m.base_color_texture is not None:
            if m.base_color_texture not in textures:
                textures.append(m.base_color_texture)
            tex_of_side[s] = textures.index(m.base_color_texture)
        if m.alpha_clip is not None:
            clip_of_side[s] = m.alpha_clip
    sizes = [t.image.size for t in textures]
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    if len(textures) == 1:  # the stored (C-contiguous) image itself
        pixels = textures[0].image.reshape(-1)
    else:
        pixels = np.concatenate([t.image.ravel() for t in textures]) if textures else np.zeros(4, np.float32)
    shape = np.array([[t.width, t.height] for t in textures] or [[1, 1]], np.int64)
    modes = np.array(
        [
            [INTERPOLATIONS.index(t.interpolation), EXTENSIONS.index(t.extension), int(t.use_alpha)]
            for t in textures
        ]
        or [[0, 0, 1]],
        np.int64,
    )
    packed = (tex_of_side, clip_of_side, kg_of_side, pixels, offsets, shape, modes)
    _PACKED[prepared] = packed
    return packed


_fetch = None  # the compiled texel fetch, set by _kernel()


@functools.lru_cache(maxsize=1)
def _kernel() -> object:  # a numba dispatcher
    import numba

    @numba.njit(inline="always", cache=True)
    def fetch(pixels, offset, w, h, ext, i, j, out, weight):  # pragma: no cover - compiled
        """out += weight · texel (column i from the left, row j from the bottom), wrapped."""
        if ext == 0:  # repeat
            i, j = i % w, j % h
        elif ext == 1:  # extend
            i, j = min(max(i, 0), w - 1), min(max(j, 0), h - 1)
        elif i < 0 or i >= w or j < 0 or j >= h:  # clip: transparent black
            return
        base = offset + ((h - 1 - j) * w + i) * 4
        for c in range(4):
            out[c] += weight * np.float64(pixels[base + c])

    # A module global, not a closure variable: numba's disk-cache key hashes closure variables,
    # and a compiled function in one changes it in every process (the kernel was never cached).
    global _fetch
    _fetch = fetch

    @numba.njit(parallel=True, cache=True)
    def run(
        triangle,
        bary,
        tris,
        uv,
        side,
        tex_of_side,
        clip_of_side,
        kg_of_side,
        pixels,
        offsets,
        shape,
        modes,
        ambient,
        diffuse,
        specular,
        rgb_in,
        alpha_in,
        mode,
        uv_limit,
    ):  # pragma: no cover - compiled
        n = len(triangle)
        rgb = rgb_in.copy()
        amb = ambient.copy()
        dif = diffuse.copy()
        alpha = alpha_in.copy()
        for f in numba.prange(n):
            s = side[f]
            k = tex_of_side[s]
            if k >= 0:
                t = triangle[f]
                u = 0.0
                v = 0.0
                for q in range(3):
                    u += bary[f, q] * uv[tris[t, q], 0]
                    v += bary[f, q] * uv[tris[t, q], 1]
                w, h = shape[k, 0], shape[k, 1]
                ext = modes[k, 1]
                # Texture.texel_coordinates: bounded before the integer conversion.
                u = min(max(u, -uv_limit), uv_limit)
                v = min(max(v, -uv_limit), uv_limit)
                if ext == 0:  # repeat: fmod(u, 1) = u − trunc(u), exact
                    u = u - np.trunc(u)
                    v = v - np.trunc(v)
                else:  # extend, clip: a whole image outside is the edge or the border
                    u = min(max(u, -1.0), 2.0)
                    v = min(max(v, -1.0), 2.0)
                x = u * w
                y = v * h
                texel = np.zeros(4)
                if modes[k, 0] == 0:  # closest
                    _fetch(pixels, offsets[k], w, h, ext, int(np.floor(x)), int(np.floor(y)), texel, 1.0)
                else:
                    x -= 0.5
                    y -= 0.5
                    fx, fy = np.floor(x), np.floor(y)
                    a, b = x - fx, y - fy
                    i0, j0 = int(fx), int(fy)
                    _fetch(pixels, offsets[k], w, h, ext, i0, j0, texel, (1 - a) * (1 - b))
                    _fetch(pixels, offsets[k], w, h, ext, i0 + 1, j0, texel, a * (1 - b))
                    _fetch(pixels, offsets[k], w, h, ext, i0, j0 + 1, texel, (1 - a) * b)
                    _fetch(pixels, offsets[k], w, h, ext, i0 + 1, j0 + 1, texel, a * b)
                    texel[3] = min(max(texel[3], 0.0), 1.0)
                if modes[k, 2] == 0:  # use_alpha=False: an RGB texture, alpha 1
                    texel[3] = 1.0
                ta = texel[3]
                for c in range(3):
                    colour = texel[c] / ta if ta > 0.0 else 0.0
                    ad = ambient[f, c] + diffuse[f, c]
                    if mode == 0:
                        rgb[f, c] = ad * colour + specular[f, c]
                    elif mode == 1:
                        sp = min(max(specular[f, c], 0.0), 1.0)
                        rgb[f, c] = min(max(min(max(ad, 0.0), 1.0) * colour + sp, 0.0), 1.0)
                    else:
                        total = min(max(ad + specular[f, c], 0.0), 1.0)
                        rgb[f, c] = min(max(total * colour, 0.0), 1.0)
                    amb[f, c] = ambient[f, c] * colour
                    dif[f, c] = diffuse[f, c] * colour
                if not kg_of_side[s]:
                    alpha[f] = alpha[f] * ta
            if clip_of_side[s] >= 0.0:
                alpha[f] = 1.0 if alpha[f] >= clip_of_side[s] else 0.0
        return rgb, amb, dif, alpha

    return run
