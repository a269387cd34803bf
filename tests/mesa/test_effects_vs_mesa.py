"""Fog, blended transparent layers and slope-scaled depth bias against Mesa llvmpipe.

Each test draws with OpenGL's fixed-function pipeline into a float framebuffer (RGBA32F,
DEPTH_COMPONENT32F) so nothing is quantised, reads it back and compares it with our
functions on the same inputs.
"""

import numpy as np
import pytest

from blinn_phong.effects.oit import resolve_a_buffer, resolve_in_draw_order
from blinn_phong.model.fog import apply_fog
from blinn_phong.model.transforms import orthographic_matrix
from blinn_phong.shadows.maps import render_shadow_map

pytestmark = pytest.mark.mesa

W = H = 32


@pytest.fixture(scope="module")
def gl(mesa_context):
    """OpenGL itself (not an oracle module), drawing into a W×H float framebuffer."""
    from OpenGL import GL

    # the context is shared with other Mesa tests: save every piece of state we touch
    GL.glPushAttrib(GL.GL_ALL_ATTRIB_BITS)
    for stack in (GL.GL_PROJECTION, GL.GL_MODELVIEW):
        GL.glMatrixMode(stack)
        GL.glPushMatrix()
    previous_fbo = GL.glGetIntegerv(GL.GL_DRAW_FRAMEBUFFER_BINDING)
    fbo = GL.glGenFramebuffers(1)
    GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fbo)
    rbs = GL.glGenRenderbuffers(2)
    GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rbs[0])
    GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_RGBA32F, W, H)
    GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_RENDERBUFFER, rbs[0])
    GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rbs[1])
    GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_DEPTH_COMPONENT32F, W, H)
    GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT, GL.GL_RENDERBUFFER, rbs[1])
    assert GL.glCheckFramebufferStatus(GL.GL_FRAMEBUFFER) == GL.GL_FRAMEBUFFER_COMPLETE
    GL.glViewport(0, 0, W, H)
    for cap in (GL.GL_DITHER, GL.GL_LIGHTING, GL.GL_TEXTURE_2D, GL.GL_CULL_FACE):
        GL.glDisable(cap)
    GL.glClampColor(GL.GL_CLAMP_READ_COLOR, GL.GL_FALSE)
    yield GL
    GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, int(previous_fbo))
    GL.glDeleteRenderbuffers(2, rbs)
    GL.glDeleteFramebuffers(1, [fbo])
    for stack in (GL.GL_PROJECTION, GL.GL_MODELVIEW):
        GL.glMatrixMode(stack)
        GL.glPopMatrix()
    GL.glPopAttrib()


def _reset(GL, clear=(0.0, 0.0, 0.0, 0.0)):
    GL.glDisable(GL.GL_FOG)
    GL.glDisable(GL.GL_BLEND)
    GL.glDisable(GL.GL_DEPTH_TEST)
    GL.glDisable(GL.GL_POLYGON_OFFSET_FILL)
    GL.glClearColor(*clear)
    GL.glClearDepth(1.0)
    GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
    GL.glMatrixMode(GL.GL_PROJECTION)
    GL.glLoadIdentity()
    GL.glMatrixMode(GL.GL_MODELVIEW)
    GL.glLoadIdentity()


def _read_rgba(GL):
    data = GL.glReadPixels(0, 0, W, H, GL.GL_RGBA, GL.GL_FLOAT)
    return np.frombuffer(data, np.float32).reshape(H, W, 4)[::-1].copy()


def _read_depth(GL):
    data = GL.glReadPixels(0, 0, W, H, GL.GL_DEPTH_COMPONENT, GL.GL_FLOAT)
    return np.frombuffer(data, np.float32).reshape(H, W)[::-1].copy()


def _rect(GL, x0, y0, x1, y1, z, colour):
    """An axis-aligned quad in window pixels (row 0 at the top) at eye depth z, ortho (0..W, 0..H)."""
    GL.glColor4f(*colour)
    GL.glBegin(GL.GL_QUADS)
    for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1)):
        GL.glVertex3f(x, H - y, z)
    GL.glEnd()


@pytest.mark.parametrize(
    "mode, params",
    [
        ("linear", {"start": 2.0, "end": 14.0}),
        ("exp", {"density": 0.15}),
        ("exp2", {"density": 0.12}),
    ],
)
def test_fog_matches_mesa_fixed_function_fog(gl, mode, params):
    GL = gl
    _reset(GL)
    GL.glMatrixMode(GL.GL_PROJECTION)
    GL.glOrtho(0, W, 0, H, 0.1, 30.0)
    GL.glMatrixMode(GL.GL_MODELVIEW)
    GL.glEnable(GL.GL_FOG)
    GL.glFogi(GL.GL_FOG_MODE, {"linear": GL.GL_LINEAR, "exp": GL.GL_EXP, "exp2": GL.GL_EXP2}[mode])
    GL.glFogf(GL.GL_FOG_DENSITY, params.get("density", 1.0))
    GL.glFogf(GL.GL_FOG_START, params.get("start", 0.0))
    GL.glFogf(GL.GL_FOG_END, params.get("end", 1.0))
    fog_colour = (0.2, 0.5, 0.9)
    GL.glFogfv(GL.GL_FOG_COLOR, (*fog_colour, 1.0))
    colour = (0.9, 0.3, 0.1, 0.6)
    distances = np.array([0.5, 1.5, 3.0, 5.0, 8.0, 11.0, 13.0, 20.0])
    for i, d in enumerate(distances):  # 8 tiles of 8×16 pixels, each at its own eye depth
        x0, y0 = (i % 4) * 8, (i // 4) * 16
        _rect(GL, x0, y0, x0 + 8, y0 + 16, -d, colour)
    GL.glFinish()
    got = _read_rgba(GL)
    tiles = np.array([got[(i // 4) * 16 + 8, (i % 4) * 8 + 4] for i in range(8)])
    premultiplied = np.tile(np.r_[np.array(colour[:3]) * colour[3], colour[3]], (8, 1))
    ours = apply_fog(premultiplied, distances, fog_colour, mode, **params)
    # OpenGL fogs the straight colour and leaves alpha alone: compare after dividing by alpha
    straight = np.c_[ours[:, :3] / ours[:, 3:], ours[:, 3]]
    np.testing.assert_allclose(tiles, straight, atol=2e-6)
    assert np.ptp(tiles[:, 0]) > 0.1  # the fog really varies over these distances


def test_layers_blended_in_draw_order_match_mesa(gl):
    """Premultiplied ``src over`` (GL_ONE, GL_ONE_MINUS_SRC_ALPHA), depth writes off, in draw order."""
    GL = gl
    background = (0.1, 0.2, 0.3, 1.0)
    _reset(GL, background)
    GL.glMatrixMode(GL.GL_PROJECTION)
    GL.glOrtho(0, W, 0, H, 0.1, 30.0)
    GL.glMatrixMode(GL.GL_MODELVIEW)
    GL.glEnable(GL.GL_BLEND)
    GL.glBlendFunc(GL.GL_ONE, GL.GL_ONE_MINUS_SRC_ALPHA)
    # overlapping rectangles: (x0, y0, x1, y1, eye depth, straight colour, alpha)
    rects = [
        (2, 2, 20, 20, 5.0, (1.0, 0.0, 0.0), 0.5),
        (10, 6, 30, 26, 2.0, (0.0, 1.0, 0.0), 0.4),
        (4, 12, 24, 30, 8.0, (0.0, 0.0, 1.0), 0.7),
        (0, 0, 16, 16, 3.0, (1.0, 1.0, 0.0), 0.25),
    ]
    draw = [2, 0, 3, 1]  # drawn in this order: back to front by depth (8, 5, 3, 2)
    pix, depth, rgba, order = [], [], [], []
    for position, r in enumerate(draw):
        x0, y0, x1, y1, z, c, a = rects[r]
        _rect(GL, x0, y0, x1, y1, -z, (*(np.array(c) * a), a))
        rows, cols = np.mgrid[y0:y1, x0:x1]
        pix.append((rows * W + cols).ravel())
        depth.append(np.full(rows.size, z))
        rgba.append(np.tile(np.r_[np.array(c) * a, a], (rows.size, 1)))
        order.append(np.full(rows.size, position))
    GL.glFinish()
    got = _read_rgba(GL).reshape(-1, 4)
    pix, depth, rgba, order = (np.concatenate(v) for v in (pix, depth, rgba, order))
    ours = resolve_in_draw_order(pix, order, rgba, W * H, np.array(background))
    np.testing.assert_allclose(ours, got, atol=2e-6)
    # drawn back to front, the result is also the A-buffer's
    np.testing.assert_allclose(
        resolve_a_buffer(pix, depth, rgba, W * H, np.array(background)), got, atol=2e-6
    )


def test_slope_scaled_bias_matches_gl_polygon_offset(gl):
    """glPolygonOffset(factor, 0) adds factor·max(|∂z/∂x|, |∂z/∂y|) to a tilted quad's depth."""
    GL = gl
    _reset(GL)
    proj = orthographic_matrix(-1, 1, -1, 1, 0.5, 5.0)
    GL.glMatrixMode(GL.GL_PROJECTION)
    GL.glLoadMatrixd(proj.T.ravel())
    GL.glMatrixMode(GL.GL_MODELVIEW)
    GL.glEnable(GL.GL_DEPTH_TEST)
    GL.glDepthFunc(GL.GL_LESS)
    tri_quad = np.array(
        [
            [[-1.0, -1.0, -1.5], [1.0, -1.0, -3.5], [1.0, 1.0, -3.0]],
            [[-1.0, -1.0, -1.5], [1.0, 1.0, -3.0], [-1.0, 1.0, -1.0]],
        ]
    )  # a plane tilted in x and y (eye space, camera at the origin looking down −z)
    factor = 4.0
    results = {}
    for offset in (0.0, factor):
        GL.glClear(GL.GL_DEPTH_BUFFER_BIT)
        if offset:
            GL.glEnable(GL.GL_POLYGON_OFFSET_FILL)
            GL.glPolygonOffset(offset, 0.0)
        else:
            GL.glDisable(GL.GL_POLYGON_OFFSET_FILL)
        GL.glBegin(GL.GL_TRIANGLES)
        for v in tri_quad.reshape(-1, 3):
            GL.glVertex3d(*v)
        GL.glEnd()
        GL.glFinish()
        results[offset] = _read_depth(GL)
        ours = render_shadow_map(tri_quad, np.eye(4), proj, W, slope_bias=offset).depth
        covered = results[offset] < 1
        assert covered.sum() > 0.9 * W * H
        np.testing.assert_allclose(ours[covered], results[offset][covered], atol=1e-6)
    shift = results[factor] - results[0.0]
    assert np.median(shift[results[0.0] < 1]) > 1e-3  # the offset is really there
