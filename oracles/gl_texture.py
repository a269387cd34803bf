"""Render a textured :class:`blinn_phong.Scene` with OpenGL fixed function (Mesa llvmpipe).

The state of :mod:`oracles.gl_lighting` (lights, materials, ``GL_SMOOTH`` per-vertex lighting,
dithering off, ``GL_NORMALIZE``) plus, for each mesh whose material has a
``base_color_texture``, texture unit 0 with:

* the image uploaded bottom row first (``Texture.gl_rows``; GL's ``t = 0`` is the first
  row), as ``GL_RGBA8`` (the texture's values must be multiples of 1/255), ``GL_RGBA32F``
  or ``GL_SRGB8_ALPHA8`` (the caller's sRGB-encoded bytes, decoded by GL before filtering);
  colour uploaded straight (GL modulates by the stored colour), or premultiplied on request;
* ``GL_TEXTURE_MIN_FILTER`` = ``GL_TEXTURE_MAG_FILTER`` = ``GL_NEAREST``/``GL_LINEAR`` (no
  mipmaps), wrap ``GL_REPEAT`` / ``GL_CLAMP_TO_EDGE`` / ``GL_CLAMP_TO_BORDER`` with a
  transparent black border (Blender's Clip);
* ``GL_TEXTURE_ENV_MODE`` = ``GL_MODULATE`` and the mesh's ``uv`` as texture coordinates;
* ``alpha_clip``: ``glAlphaFunc(GL_GEQUAL, alpha_clip)`` with ``GL_ALPHA_TEST``.

Output: uint8 RGBA, row 0 at the TOP. Used only by tests. Call
:func:`oracles.egl.gl_context` before anything imports OpenGL.
"""

from __future__ import annotations

import time

import numpy as np

from blinn_phong.model.scene import Scene
from blinn_phong.model.texture import Texture, straight_colour
from oracles.egl import gl_context
from oracles.gl_common import Framebuffer
from oracles.gl_lighting import GLRender, _mesh_normals, _set_material, _set_state

__all__ = ["FORMATS", "render_textured"]

FORMATS = ("rgba8", "rgba32f", "srgb8_alpha8")


def _upload(gl, texture: Texture, fmt: str, encoded: np.ndarray | None, premultiplied: bool) -> int:
    """A GL texture object holding ``texture`` (or the sRGB ``encoded`` uint8 bytes)."""
    name = gl.glGenTextures(1)
    gl.glBindTexture(gl.GL_TEXTURE_2D, name)
    gl.glPixelStorei(gl.GL_UNPACK_ALIGNMENT, 1)
    h, w = texture.height, texture.width
    rows = texture.gl_rows().reshape(-1, 4)
    straight = np.concatenate([straight_colour(rows), rows[:, 3:4]], axis=1).reshape(h, w, 4)
    if premultiplied:
        straight = texture.gl_rows().astype(np.float64)
    if fmt == "rgba8":
        data = np.rint(straight * 255.0)
        if np.abs(data - straight * 255.0).max() > 1e-3:
            raise ValueError("texture: rgba8 upload needs values that are multiples of 1/255")
        internal, pixel_type, pixels = gl.GL_RGBA8, gl.GL_UNSIGNED_BYTE, data.astype(np.uint8)
    elif fmt == "rgba32f":
        internal, pixel_type, pixels = gl.GL_RGBA32F, gl.GL_FLOAT, straight.astype(np.float32)
    elif fmt == "srgb8_alpha8":
        if encoded is None or encoded.dtype != np.uint8 or encoded.shape != (h, w, 4):
            raise ValueError(f"encoded: expected (H, W, 4) = ({h}, {w}, 4) uint8 sRGB bytes for srgb8_alpha8")
        internal, pixel_type, pixels = gl.GL_SRGB8_ALPHA8, gl.GL_UNSIGNED_BYTE, encoded[::-1]
    else:
        raise ValueError(f"fmt: expected one of {FORMATS}, got {fmt!r}")
    gl.glTexImage2D(
        gl.GL_TEXTURE_2D, 0, internal, w, h, 0, gl.GL_RGBA, pixel_type, np.ascontiguousarray(pixels)
    )
    filt = gl.GL_NEAREST if texture.interpolation == "closest" else gl.GL_LINEAR
    wrap = {"repeat": gl.GL_REPEAT, "extend": gl.GL_CLAMP_TO_EDGE, "clip": gl.GL_CLAMP_TO_BORDER}[
        texture.extension
    ]
    gl.glTexParameteri(gl.GL_TEXTURE_2D, gl.GL_TEXTURE_MIN_FILTER, filt)
    gl.glTexParameteri(gl.GL_TEXTURE_2D, gl.GL_TEXTURE_MAG_FILTER, filt)
    gl.glTexParameteri(gl.GL_TEXTURE_2D, gl.GL_TEXTURE_WRAP_S, wrap)
    gl.glTexParameteri(gl.GL_TEXTURE_2D, gl.GL_TEXTURE_WRAP_T, wrap)
    gl.glTexParameterfv(gl.GL_TEXTURE_2D, gl.GL_TEXTURE_BORDER_COLOR, (0.0, 0.0, 0.0, 0.0))
    gl.glTexParameteri(gl.GL_TEXTURE_2D, gl.GL_TEXTURE_MAX_LEVEL, 0)
    return int(name)


def render_textured(
    scene: Scene,
    width: int,
    height: int,
    *,
    fmt: str = "rgba8",
    encoded: np.ndarray | None = None,
    premultiplied: bool = False,
) -> GLRender:
    """Render ``scene`` with fixed-function lighting and ``GL_MODULATE`` textures (module docstring).

    Args:
        scene: meshes with ``uv`` where their material has a ``base_color_texture``.
        width: framebuffer width in pixels.
        height: framebuffer height in pixels.
        fmt: the internal format of every texture: ``"rgba8"``, ``"rgba32f"`` or ``"srgb8_alpha8"``.
        encoded: for ``"srgb8_alpha8"``: the (H, W, 4) uint8 sRGB-encoded image, row 0 at the top.
        premultiplied: upload the premultiplied texels instead of the straight colour: GL then
            filters premultiplied values as :class:`~blinn_phong.model.texture.Texture` does and
            writes ``Cf·Σw·(a·c)`` — the premultiplied colour of an unlit-specular surface.

    Raises :class:`oracles.egl.EGLUnavailable` when no context can be created.
    """
    info = gl_context()
    from OpenGL import GL

    gl = GL
    fb = Framebuffer(gl, width, height)
    textures: list[int] = []
    try:
        start = time.perf_counter()
        _set_state(gl, scene, flat=False)
        gl.glHint(gl.GL_PERSPECTIVE_CORRECTION_HINT, gl.GL_NICEST)
        gl.glTexEnvi(gl.GL_TEXTURE_ENV, gl.GL_TEXTURE_ENV_MODE, gl.GL_MODULATE)
        for mesh in scene.meshes:
            material = mesh.material
            _set_material(gl, gl.GL_FRONT_AND_BACK, material)
            if mesh.back_material is not None:
                _set_material(gl, gl.GL_BACK, mesh.back_material)
            texture = material.base_color_texture
            if texture is not None:
                textures.append(_upload(gl, texture, fmt, encoded, premultiplied))
                gl.glEnable(gl.GL_TEXTURE_2D)
            else:
                gl.glDisable(gl.GL_TEXTURE_2D)
            if material.alpha_clip is not None:
                gl.glEnable(gl.GL_ALPHA_TEST)
                gl.glAlphaFunc(gl.GL_GEQUAL, material.alpha_clip)
            else:
                gl.glDisable(gl.GL_ALPHA_TEST)
            gl.glMatrixMode(gl.GL_MODELVIEW)
            gl.glLoadMatrixd(np.ascontiguousarray((scene.camera.view @ mesh.transform).T))
            positions = np.ascontiguousarray(mesh.positions, dtype=np.float32)
            normals = np.ascontiguousarray(_mesh_normals(mesh), dtype=np.float32)
            uv = np.zeros((len(positions), 2)) if mesh.uv is None else mesh.uv
            uv = np.ascontiguousarray(uv, dtype=np.float32)
            gl.glBegin(gl.GL_TRIANGLES)
            for tri in mesh.triangles:
                for v in tri:
                    gl.glTexCoord2fv(uv[v])
                    gl.glNormal3fv(normals[v])
                    gl.glVertex3fv(positions[v])
            gl.glEnd()
        gl.glFinish()
        seconds = time.perf_counter() - start
        return GLRender(fb.read(), seconds, info.renderer, depth=fb.read_depth())
    finally:
        gl.glDisable(gl.GL_TEXTURE_2D)
        gl.glDisable(gl.GL_ALPHA_TEST)
        if textures:
            gl.glDeleteTextures(textures)
        fb.delete()
