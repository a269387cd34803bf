"""Stenciled shadow volumes drawn by a real OpenGL implementation (Mesa llvmpipe).

The reference for :mod:`blinn_phong.shadows.volume`: the same scene and light are drawn by
OpenGL into a framebuffer object with a ``GL_DEPTH24_STENCIL8`` attachment, following
Everitt & Kilgard ("Practical and Robust Stenciled Shadow Volumes", NVIDIA 2002):

1. depth pass: every scene triangle, ``glDepthFunc(GL_LESS)``, colour writes off;
2. stencil pass: depth writes off, ``glStencilFunc(GL_ALWAYS)``, no face culling, both faces
   in one draw with ``glStencilOpSeparate`` (OpenGL 2.0):
   * z-pass (Heidmann): front faces ``GL_INCR_WRAP`` on depth pass, back faces ``GL_DECR_WRAP``;
   * z-fail: back faces ``GL_INCR_WRAP`` on depth fail, front faces ``GL_DECR_WRAP``, with
     ``GL_DEPTH_CLAMP`` (OpenGL 3.2) so volume faces at infinity are not clipped by the far plane;
3. the stencil buffer is read back: 0 = lit.

The volumes are built here independently of :mod:`blinn_phong.shadows.volume`, by the simplest
correct construction (no adjacency, no silhouettes): every scene triangle, turned to face the
light, is extruded on its own — light cap, three side quads and a dark cap at infinity
(homogeneous ``w = 0``). A point is inside as many of these as there are triangles between it
and the light.

Both passes submit the same 4-component double vertices with the same matrices, so a surface
and its own light cap get identical depths (OpenGL's invariance rules, OpenGL 2.1 appendix A)
and the cap fails ``GL_LESS``. Output rows are flipped to row 0 at the top.

Used only by tests and benchmarks. Call :func:`oracles.egl.gl_context` before anything imports
OpenGL (this module imports it lazily).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.model.scene import Scene
from oracles.egl import gl_context
from oracles.gl_common import Framebuffer, world_triangles

__all__ = ["StencilRender", "per_triangle_volumes", "render_stencil_shadows"]


@dataclass(frozen=True)
class StencilRender:
    """A stencil shadow pass read back.

    ``stencil``: (H, W) uint8 count modulo 256 (0 = lit), row 0 at the top; ``depth``: (H, W)
    float32 window depth of the scene (1 where empty); ``seconds``: wall time of both passes
    (upload, draw and ``glFinish``); ``renderer``: the ``GL_RENDERER`` string.
    """

    stencil: np.ndarray
    depth: np.ndarray
    seconds: float
    renderer: str


def per_triangle_volumes(
    world_triangles: np.ndarray, light: DirectionalLight | PointLight | SpotLight, *, caps: bool = True
) -> np.ndarray:
    """Every triangle's own shadow volume, outward (counter-clockwise from outside), homogeneous.

    Returns (m, 3, 4) float64: per triangle facing the light (reversed if it faces away; skipped
    when edge-on) its light cap, three side quads (two triangles each) and, with ``caps``, the
    light cap and the dark cap at infinity.
    """
    tris = np.asarray(world_triangles, dtype=np.float64)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    if isinstance(light, DirectionalLight):
        d = np.asarray(light.direction, dtype=np.float64)
        side = -(n @ d)
    else:
        lp = np.asarray(light.position, dtype=np.float64)
        side = np.einsum("ij,ij->i", n, lp - tris[:, 0])
    tris = np.where((side < 0)[:, None, None], tris[:, ::-1], tris)[side != 0]

    def far(v: np.ndarray) -> np.ndarray:  # (k, 3) -> (k, 4) at infinity, away from the light
        away = np.broadcast_to(d, v.shape) if isinstance(light, DirectionalLight) else v - lp
        return np.c_[away, np.zeros(len(v))]

    def near(v: np.ndarray) -> np.ndarray:
        return np.c_[v, np.ones(len(v))]

    out = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        a, b = tris[:, i], tris[:, j]
        # the face faces the light, so its interior is left of a→b seen from the light; the side
        # (b, a, a∞, b∞) then faces away from that interior
        out.append(np.stack([near(b), near(a), far(a)], axis=1))
        out.append(np.stack([near(b), far(a), far(b)], axis=1))
    if caps:
        out.append(np.stack([near(tris[:, 0]), near(tris[:, 1]), near(tris[:, 2])], axis=1))
        out.append(np.stack([far(tris[:, 2]), far(tris[:, 1]), far(tris[:, 0])], axis=1))
    return np.concatenate(out)


def render_stencil_shadows(
    scene: Scene,
    light: DirectionalLight | PointLight | SpotLight,
    width: int,
    height: int,
    *,
    method: str = "zfail",
    volumes: np.ndarray | None = None,
) -> StencilRender:
    """Draw ``scene``'s depth and ``light``'s shadow volumes into a stencil buffer with OpenGL.

    Args:
        scene: the scene (its camera's view and projection are loaded as GL matrices).
        light: the light casting the volumes.
        width: framebuffer width in pixels.
        height: framebuffer height in pixels.
        method: ``"zfail"`` (with ``GL_DEPTH_CLAMP``) or ``"zpass"``.
        volumes: (m, 3, 4) homogeneous world-space volume triangles to draw instead of
            :func:`per_triangle_volumes` (e.g. a deliberately broken volume).

    Raises :class:`oracles.egl.EGLUnavailable` when no context can be created.
    """
    if method not in ("zfail", "zpass"):
        raise ValueError(f"method: expected 'zfail' or 'zpass', got {method!r}")
    info = gl_context()
    from OpenGL import GL

    gl = GL

    tris = world_triangles(scene)
    if volumes is None:
        volumes = per_triangle_volumes(tris, light, caps=method == "zfail")
    scene_v = np.ascontiguousarray(np.c_[tris.reshape(-1, 3), np.ones(3 * len(tris))], dtype=np.float64)
    volume_v = np.ascontiguousarray(np.asarray(volumes, dtype=np.float64).reshape(-1, 4))

    gl.glPushAttrib(gl.GL_ALL_ATTRIB_BITS)
    for stack in (gl.GL_PROJECTION, gl.GL_MODELVIEW):
        gl.glMatrixMode(stack)
        gl.glPushMatrix()
    previous_fbo = gl.glGetIntegerv(gl.GL_DRAW_FRAMEBUFFER_BINDING)
    fb = None
    try:
        fb = Framebuffer(gl, width, height, stencil=True)
        start = time.perf_counter()
        gl.glMatrixMode(gl.GL_PROJECTION)
        gl.glLoadMatrixd(np.ascontiguousarray(scene.camera.projection.T))
        gl.glMatrixMode(gl.GL_MODELVIEW)
        gl.glLoadMatrixd(np.ascontiguousarray(scene.camera.view.T))
        gl.glDisable(gl.GL_LIGHTING)
        gl.glDisable(gl.GL_CULL_FACE)
        gl.glDisable(gl.GL_DITHER)
        gl.glFrontFace(gl.GL_CCW)
        gl.glClearDepth(1.0)
        gl.glClearStencil(0)
        gl.glClearColor(0.0, 0.0, 0.0, 0.0)
        gl.glClear(gl.GL_COLOR_BUFFER_BIT | gl.GL_DEPTH_BUFFER_BIT | gl.GL_STENCIL_BUFFER_BIT)
        gl.glEnableClientState(gl.GL_VERTEX_ARRAY)
        # 1. depth of the scene
        gl.glColorMask(gl.GL_FALSE, gl.GL_FALSE, gl.GL_FALSE, gl.GL_FALSE)
        gl.glEnable(gl.GL_DEPTH_TEST)
        gl.glDepthFunc(gl.GL_LESS)
        gl.glDepthMask(gl.GL_TRUE)
        gl.glDisable(gl.GL_STENCIL_TEST)
        gl.glVertexPointer(4, gl.GL_DOUBLE, 0, scene_v)
        gl.glDrawArrays(gl.GL_TRIANGLES, 0, len(scene_v))
        # 2. count volume faces
        gl.glDepthMask(gl.GL_FALSE)
        gl.glEnable(gl.GL_STENCIL_TEST)
        gl.glStencilMask(0xFF)
        gl.glStencilFunc(gl.GL_ALWAYS, 0, 0xFF)
        if method == "zpass":
            gl.glStencilOpSeparate(gl.GL_FRONT, gl.GL_KEEP, gl.GL_KEEP, gl.GL_INCR_WRAP)
            gl.glStencilOpSeparate(gl.GL_BACK, gl.GL_KEEP, gl.GL_KEEP, gl.GL_DECR_WRAP)
        else:
            gl.glEnable(gl.GL_DEPTH_CLAMP)
            gl.glStencilOpSeparate(gl.GL_FRONT, gl.GL_KEEP, gl.GL_DECR_WRAP, gl.GL_KEEP)
            gl.glStencilOpSeparate(gl.GL_BACK, gl.GL_KEEP, gl.GL_INCR_WRAP, gl.GL_KEEP)
        if len(volume_v):
            gl.glVertexPointer(4, gl.GL_DOUBLE, 0, volume_v)
            gl.glDrawArrays(gl.GL_TRIANGLES, 0, len(volume_v))
        gl.glFinish()
        seconds = time.perf_counter() - start
        gl.glDisableClientState(gl.GL_VERTEX_ARRAY)
        stencil = fb.read_stencil()
        depth = fb.read_depth()
    finally:
        if fb is not None:
            fb.delete()
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, int(previous_fbo))
        for stack in (gl.GL_MODELVIEW, gl.GL_PROJECTION):
            gl.glMatrixMode(stack)
            gl.glPopMatrix()
        gl.glPopAttrib()
    return StencilRender(stencil, depth, seconds, info.renderer)
