"""Two-pass shadow mapping with a real OpenGL implementation (Mesa llvmpipe, GLSL).

:func:`render_shadow_mapped` draws a :class:`blinn_phong.Scene` the way a GL application
does shadow mapping (Williams 1978):

1. **Depth pass**, once per light camera: every mesh is drawn from the light into one layer
   of a ``GL_DEPTH_COMPONENT32F`` 2D array texture of ``resolution²`` texels, with
   ``glPolygonOffset(slope_bias, 0)`` (OpenGL 2.1 §3.5.5: the implementation adds
   ``slope_bias·max(|∂z/∂x|, |∂z/∂y|)``, clamped to [0, 1]), both faces, ``GL_LESS``.
   The light cameras are those of :func:`blinn_phong.shadows.maps.light_cameras` (an
   orthographic camera for a directional light, a perspective one for a spot, six cube
   faces for a point light) — the set-up, like the scene's own camera, is an input.
2. **Lighting pass**: the per-pixel Blinn-Phong GLSL program of
   :mod:`oracles.gl_lighting` (same state, same built-in uniforms), extended with a
   per-light visibility that multiplies the light's diffuse and specular terms. The
   fragment's world position is projected by the light camera; a point light picks the
   cube face of the major axis; the depth comparison ``z ≤ stored + constant_bias`` is
   made with ``texelFetch`` at the taps of the same percentage-closer kernel
   (``nearest``, ``bilinear`` — the 2×2 taps weighted bilinearly —, ``box3/5/7``), taps
   clamped to the map; points outside the light's frustum are lit.

Output: uint8 RGBA, row 0 at the top, background (0, 0, 0, 0); optionally the depth maps
read back (float32, row 0 at the top, as :class:`blinn_phong.shadows.maps.ShadowMap` stores them).
Used only by tests and benchmarks. Raises :class:`oracles.egl.EGLUnavailable` when no
context can be created.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from blinn_phong.frame.lighting import lights_in_eye_space
from blinn_phong.model.lights import AmbientLight
from blinn_phong.model.scene import Scene
from blinn_phong.shadows.maps import PCF_KERNELS, light_cameras
from oracles.egl import gl_context
from oracles.gl_common import Framebuffer, blinn_phong_main, compile_program, world_triangles
from oracles.gl_lighting import MAX_LIGHTS, _MeshBuffers, _set_state

__all__ = ["ShadowGLRender", "render_shadow_mapped"]

MAX_LAYERS = 6 * MAX_LIGHTS

_VERTEX_SHADER = """
#version 130
uniform mat4 eye_to_world;
out vec3 v_position;
out vec3 v_normal;
out vec3 v_world;
void main() {
    vec4 eye = gl_ModelViewMatrix * gl_Vertex;
    v_position = eye.xyz;
    v_normal = normalize(gl_NormalMatrix * gl_Normal);
    v_world = (eye_to_world * eye).xyz;
    gl_Position = gl_ProjectionMatrix * eye;
}
"""

_FRAGMENT_SHADER = """
#version 130
uniform int n_lights;
uniform bool local_viewer;
uniform bool two_sided;
uniform sampler2DArray shadow_maps;
uniform int first_layer[8];
uniform int n_faces[8];          // 0: no shadow; 1: one map; 6: cube faces +x -x +y -y +z -z
uniform vec3 light_world[8];     // point-light positions (cube face choice)
uniform mat4 layer_vp[48];       // world -> light clip, per layer
uniform float constant_bias;
uniform int kernel;              // 0 nearest, 1 bilinear, k for a k x k box
uniform float res;
in vec3 v_position;
in vec3 v_normal;
in vec3 v_world;

float lit_at(int layer, float col, float row, float z) {
    int c = int(clamp(col, 0.0, res - 1.0));
    int r = int(clamp(row, 0.0, res - 1.0));
    return (z <= texelFetch(shadow_maps, ivec3(c, r, layer), 0).r + constant_bias) ? 1.0 : 0.0;
}

float visibility(int i) {
    if (n_faces[i] == 0) return 1.0;
    int layer = first_layer[i];
    if (n_faces[i] == 6) {
        vec3 r = v_world - light_world[i];
        int axis = 0;
        float best = abs(r.x);
        float val = r.x;
        if (abs(r.y) > best) { axis = 1; best = abs(r.y); val = r.y; }
        if (abs(r.z) > best) { axis = 2; best = abs(r.z); val = r.z; }
        if (val == 0.0) return 1.0;
        layer += 2 * axis + (val > 0.0 ? 0 : 1);
    }
    vec4 c = layer_vp[layer] * vec4(v_world, 1.0);
    if (!(c.w > 0.0)) return 1.0;
    vec3 ndc = c.xyz / c.w;
    float z = (ndc.z + 1.0) * 0.5;
    if (ndc.x < -1.0 || ndc.x > 1.0 || ndc.y < -1.0 || ndc.y > 1.0 || z > 1.0) return 1.0;
    float x = (ndc.x + 1.0) * 0.5 * res;
    float y = (ndc.y + 1.0) * 0.5 * res;  // texel rows from the bottom, as GL stores them
    if (kernel == 0) return lit_at(layer, floor(x), floor(y), z);
    if (kernel == 1) {
        float fx = x - 0.5;
        float fy = y - 0.5;
        float x0 = floor(fx);
        float y0 = floor(fy);
        float tx = fx - x0;
        float ty = fy - y0;
        float l00 = lit_at(layer, x0, y0, z);
        float l10 = lit_at(layer, x0 + 1.0, y0, z);
        float l01 = lit_at(layer, x0, y0 + 1.0, z);
        float l11 = lit_at(layer, x0 + 1.0, y0 + 1.0, z);
        float a = l00 + tx * (l10 - l00);
        float b = l01 + tx * (l11 - l01);
        return a + ty * (b - a);
    }
    int h = (kernel - 1) / 2;
    float total = 0.0;
    for (int oy = -h; oy <= h; oy++)
        for (int ox = -h; ox <= h; ox++)
            total += lit_at(layer, floor(x) + float(ox), floor(y) + float(oy), z);
    return total / float(kernel * kernel);
}

""" + blinn_phong_main("visibility(i)")


@dataclass(frozen=True)
class ShadowGLRender:
    """A shadow-mapped OpenGL frame read back.

    ``rgba``: uint8 (H, W, 4), row 0 at the top. ``seconds``: wall time per frame (every
    depth pass, the lighting pass and ``glFinish``; geometry already in buffer objects);
    ``cpu_seconds``: process CPU time per frame (llvmpipe's threads included).
    ``maps``: float32 (layers, R, R) depth maps, row 0 at the top, when requested, in the
    order of the scene's lights (one layer per directional or spot light, six per point light).
    """

    rgba: np.ndarray
    seconds: float
    cpu_seconds: float
    renderer: str
    maps: np.ndarray | None = None


_PROGRAM: dict[str, int] = {}


def _program(gl) -> int:
    if "shadow" in _PROGRAM:
        return _PROGRAM["shadow"]
    program = compile_program(gl, _VERTEX_SHADER, _FRAGMENT_SHADER)
    _PROGRAM["shadow"] = program
    return program


def render_shadow_mapped(
    scene: Scene,
    width: int,
    height: int,
    *,
    resolution: int = 1024,
    constant_bias: float = 1e-4,
    slope_bias: float = 2.0,
    kernel: str = "nearest",
    repeats: int = 1,
    read_maps: bool = False,
) -> ShadowGLRender:
    """Render ``scene`` with shadow maps for every non-ambient light (see the module docstring).

    Args:
        scene: the scene (at most 8 non-ambient lights).
        width: image width in pixels.
        height: image height in pixels.
        resolution: shadow-map texels per side.
        constant_bias: window-depth units added to the stored depth in the comparison.
        slope_bias: ``glPolygonOffset`` factor of the depth pass.
        kernel: one of :data:`blinn_phong.shadows.maps.PCF_KERNELS`.
        repeats: frames drawn and timed after one untimed warm-up frame.
        read_maps: also read the depth maps back.

    Returns:
        :class:`ShadowGLRender`.
    """
    if kernel not in PCF_KERNELS:
        raise ValueError(f"kernel must be one of {PCF_KERNELS}, got {kernel!r}")
    if not isinstance(resolution, int) or resolution < 1:
        raise ValueError(f"resolution must be an integer >= 1, got {resolution!r}")
    info = gl_context()
    from OpenGL import GL

    gl = GL
    tris = world_triangles(scene)
    lights = lights_in_eye_space(scene.lights, scene.camera.view)
    if len(lights) > MAX_LIGHTS:
        raise ValueError(f"scene.lights: at most {MAX_LIGHTS} non-ambient lights, got {len(lights)}")
    # layers of every GL light (GL light i is scene light lights.source[i])
    first, faces, light_world, layer_vp = [], [], [], []
    for i in range(len(lights)):
        light = scene.lights[int(lights.source[i])]
        cams = [] if isinstance(light, AmbientLight) else light_cameras(light, tris)
        first.append(len(layer_vp))
        faces.append(len(cams))
        light_world.append(np.asarray(getattr(light, "position", (0.0, 0.0, 0.0)), dtype=np.float64))
        layer_vp += [proj @ view for view, proj in cams]
    n_layers = max(len(layer_vp), 1)

    res = int(resolution)
    tex = gl.glGenTextures(1)
    gl.glBindTexture(gl.GL_TEXTURE_2D_ARRAY, tex)
    gl.glTexImage3D(
        gl.GL_TEXTURE_2D_ARRAY, 0, gl.GL_DEPTH_COMPONENT32F, res, res, n_layers, 0,
        gl.GL_DEPTH_COMPONENT, gl.GL_FLOAT, None,
    )  # fmt: skip
    for name in (gl.GL_TEXTURE_MIN_FILTER, gl.GL_TEXTURE_MAG_FILTER):
        gl.glTexParameteri(gl.GL_TEXTURE_2D_ARRAY, name, gl.GL_NEAREST)
    gl.glTexParameteri(gl.GL_TEXTURE_2D_ARRAY, gl.GL_TEXTURE_COMPARE_MODE, gl.GL_NONE)
    gl.glBindTexture(gl.GL_TEXTURE_2D_ARRAY, 0)
    depth_fbos = gl.glGenFramebuffers(n_layers)
    depth_fbos = [int(f) for f in np.atleast_1d(depth_fbos)]
    for layer, fbo in enumerate(depth_fbos):
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, fbo)
        gl.glFramebufferTextureLayer(gl.GL_FRAMEBUFFER, gl.GL_DEPTH_ATTACHMENT, tex, 0, layer)
        gl.glDrawBuffer(gl.GL_NONE)
        gl.glReadBuffer(gl.GL_NONE)
        status = gl.glCheckFramebufferStatus(gl.GL_FRAMEBUFFER)
        if status != gl.GL_FRAMEBUFFER_COMPLETE:
            raise RuntimeError(f"depth framebuffer incomplete: status 0x{int(status):x}")

    fb = Framebuffer(gl, width, height)
    buffers = _MeshBuffers(gl, scene)
    program = _program(gl)
    try:

        def depth_passes() -> None:
            gl.glUseProgram(0)
            gl.glDisable(gl.GL_LIGHTING)
            gl.glDisable(gl.GL_CULL_FACE)
            gl.glEnable(gl.GL_DEPTH_TEST)
            gl.glDepthFunc(gl.GL_LESS)
            gl.glColorMask(gl.GL_FALSE, gl.GL_FALSE, gl.GL_FALSE, gl.GL_FALSE)
            gl.glEnable(gl.GL_POLYGON_OFFSET_FILL)
            gl.glPolygonOffset(float(slope_bias), 0.0)
            gl.glViewport(0, 0, res, res)
            gl.glEnableClientState(gl.GL_VERTEX_ARRAY)
            for layer, vp_fbo in enumerate(depth_fbos[: len(layer_vp)]):
                gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, vp_fbo)
                gl.glClearDepth(1.0)
                gl.glClear(gl.GL_DEPTH_BUFFER_BIT)
                gl.glMatrixMode(gl.GL_PROJECTION)
                gl.glLoadMatrixd(np.ascontiguousarray(layer_vp[layer].T))
                for mesh, (vbo, _, ibo), count in buffers.items:
                    gl.glMatrixMode(gl.GL_MODELVIEW)
                    gl.glLoadMatrixd(np.ascontiguousarray(mesh.transform.T))
                    gl.glBindBuffer(gl.GL_ARRAY_BUFFER, vbo)
                    gl.glVertexPointer(3, gl.GL_FLOAT, 0, None)
                    gl.glBindBuffer(gl.GL_ELEMENT_ARRAY_BUFFER, ibo)
                    gl.glDrawElements(gl.GL_TRIANGLES, count, gl.GL_UNSIGNED_INT, None)
            gl.glBindBuffer(gl.GL_ARRAY_BUFFER, 0)
            gl.glBindBuffer(gl.GL_ELEMENT_ARRAY_BUFFER, 0)
            gl.glDisableClientState(gl.GL_VERTEX_ARRAY)
            gl.glDisable(gl.GL_POLYGON_OFFSET_FILL)
            gl.glColorMask(gl.GL_TRUE, gl.GL_TRUE, gl.GL_TRUE, gl.GL_TRUE)

        def lighting_pass() -> None:
            gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, fb.fbo)
            gl.glViewport(0, 0, width, height)
            gl.glUseProgram(program)
            n = _set_state(gl, scene, flat=False)

            def loc(name: str) -> int:
                return gl.glGetUniformLocation(program, name)

            gl.glUniform1i(loc("n_lights"), n)
            gl.glUniform1i(loc("local_viewer"), int(scene.light_model.local_viewer))
            gl.glUniform1i(loc("two_sided"), int(scene.light_model.two_sided))
            gl.glUniformMatrix4fv(
                loc("eye_to_world"), 1, gl.GL_TRUE, np.linalg.inv(scene.camera.view).astype(np.float32)
            )
            gl.glUniform1iv(loc("first_layer"), len(first), np.asarray(first, np.int32))
            gl.glUniform1iv(loc("n_faces"), len(faces), np.asarray(faces, np.int32))
            gl.glUniform3fv(loc("light_world"), len(light_world), np.asarray(light_world, np.float32))
            if layer_vp:
                gl.glUniformMatrix4fv(
                    loc("layer_vp"), len(layer_vp), gl.GL_TRUE, np.asarray(layer_vp, np.float32)
                )
            gl.glUniform1f(loc("constant_bias"), float(constant_bias))
            code = (
                {"nearest": 0, "bilinear": 1}[kernel]
                if kernel in ("nearest", "bilinear")
                else int(kernel[3:])
            )
            gl.glUniform1i(loc("kernel"), code)
            gl.glUniform1f(loc("res"), float(res))
            gl.glActiveTexture(gl.GL_TEXTURE0)
            gl.glBindTexture(gl.GL_TEXTURE_2D_ARRAY, tex)
            gl.glUniform1i(loc("shadow_maps"), 0)
            buffers.draw(scene)
            gl.glBindTexture(gl.GL_TEXTURE_2D_ARRAY, 0)
            gl.glUseProgram(0)

        depth_passes()  # warm-up: shader variants, buffer upload
        lighting_pass()
        gl.glFinish()
        start, cpu_start = time.perf_counter(), time.process_time()
        for _ in range(max(repeats, 1)):
            depth_passes()
            lighting_pass()
            gl.glFinish()
        seconds = (time.perf_counter() - start) / max(repeats, 1)
        cpu_seconds = (time.process_time() - cpu_start) / max(repeats, 1)
        image = fb.read()
        maps = None
        if read_maps and layer_vp:
            gl.glBindTexture(gl.GL_TEXTURE_2D_ARRAY, tex)
            gl.glPixelStorei(gl.GL_PACK_ALIGNMENT, 1)
            data = gl.glGetTexImage(gl.GL_TEXTURE_2D_ARRAY, 0, gl.GL_DEPTH_COMPONENT, gl.GL_FLOAT)
            gl.glBindTexture(gl.GL_TEXTURE_2D_ARRAY, 0)
            stack = np.frombuffer(data, np.float32).reshape(n_layers, res, res)[: len(layer_vp)]
            maps = stack[:, ::-1].copy()  # GL rows are bottom-up
        return ShadowGLRender(image, seconds, cpu_seconds, info.renderer, maps)
    finally:
        buffers.delete()
        fb.delete()
        gl.glDeleteFramebuffers(len(depth_fbos), depth_fbos)
        gl.glDeleteTextures(1, [tex])
