"""Render a :class:`blinn_phong.Scene` with a real OpenGL implementation (Mesa llvmpipe).

Two drivers, both drawing the same geometry with the same GL state:

* :func:`render_fixed_function` — OpenGL 2.1 fixed-function lighting
  (``glLight*``, ``glMaterial*``, ``glLightModel*``), ``GL_SMOOTH`` or ``GL_FLAT``;
* :func:`render_glsl_phong` — a small GLSL 1.20 program evaluating the same
  lighting equation per pixel (interpolated eye-space position and normal),
  reading the light and material state from the built-in uniforms
  (``gl_LightSource``, ``gl_FrontMaterial``...).

Comparison hygiene (see docs/renderer.md): dithering off, ``GL_NORMALIZE`` on,
lights specified under an identity modelview (their eye-space positions are
computed here in float64), global ambient set explicitly, depth test ``GL_LESS``.
Output: uint8 RGBA, row 0 at the TOP (flipped from OpenGL's bottom-up readback),
background (0, 0, 0, 0) so alpha marks coverage.

Used only by tests and benchmarks. Call :func:`oracles.egl.gl_context` before
anything imports OpenGL (this module imports it lazily).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from blinn_phong.frame.lighting import lights_in_eye_space
from blinn_phong.geometry.normals import vertex_normals
from blinn_phong.model.scene import Mesh, Scene
from oracles.egl import gl_context
from oracles.gl_common import Framebuffer, blinn_phong_main, compile_program

__all__ = ["GLRender", "render_fixed_function", "render_glsl_phong"]

MAX_LIGHTS = 8

_VERTEX_SHADER = """
#version 120
varying vec3 v_position;
varying vec3 v_normal;
void main() {
    vec4 eye = gl_ModelViewMatrix * gl_Vertex;
    v_position = eye.xyz;
    v_normal = normalize(gl_NormalMatrix * gl_Normal);  // unit per vertex, as GL_NORMALIZE does
    gl_Position = gl_ProjectionMatrix * eye;
}
"""

# The OpenGL 2.1 §2.14.1 equation per fragment (Blinn half vector), all lights' state from built-ins.
_FRAGMENT_SHADER = """
#version 120
uniform int n_lights;
uniform bool local_viewer;
uniform bool two_sided;
varying vec3 v_position;
varying vec3 v_normal;
""" + blinn_phong_main()


@dataclass(frozen=True)
class GLRender:
    """An OpenGL render read back: ``rgba`` uint8 (H, W, 4), row 0 at the top; ``seconds`` to draw + finish.

    ``renderer`` is the ``GL_RENDERER`` string; ``cpu_seconds`` the process CPU time of the
    timed frames (llvmpipe's worker threads run in this process), per frame; ``depth`` the
    (H, W) float32 window depth read from the 24-bit depth buffer (1.0 where nothing was drawn),
    row 0 at the top.
    """

    rgba: np.ndarray
    seconds: float
    renderer: str
    cpu_seconds: float = float("nan")
    depth: np.ndarray | None = None


def _mesh_normals(mesh: Mesh) -> np.ndarray:
    if mesh.normals is not None:
        return mesh.normals
    return vertex_normals(mesh.positions, mesh.triangles, mesh.normal_weighting)


def _set_state(gl, scene: Scene, *, flat: bool) -> int:
    """Lighting, material-independent state; returns the number of GL lights used."""
    gl.glDisable(gl.GL_DITHER)
    gl.glEnable(gl.GL_DEPTH_TEST)
    gl.glDepthFunc(gl.GL_LESS)
    gl.glDisable(gl.GL_CULL_FACE)
    gl.glEnable(gl.GL_NORMALIZE)
    gl.glEnable(gl.GL_LIGHTING)
    gl.glShadeModel(gl.GL_FLAT if flat else gl.GL_SMOOTH)
    gl.glClearColor(0.0, 0.0, 0.0, 0.0)
    gl.glClearDepth(1.0)
    gl.glClear(gl.GL_COLOR_BUFFER_BIT | gl.GL_DEPTH_BUFFER_BIT)

    lights = lights_in_eye_space(scene.lights, scene.camera.view)
    if len(lights) > MAX_LIGHTS:
        raise ValueError(
            f"scene.lights: OpenGL fixed function has {MAX_LIGHTS} lights, the scene has {len(lights)}"
        )
    model = scene.light_model
    global_ambient = np.asarray(scene.ambient) + lights.ambient_lights
    gl.glLightModelfv(gl.GL_LIGHT_MODEL_AMBIENT, (*global_ambient, 1.0))
    gl.glLightModeli(gl.GL_LIGHT_MODEL_LOCAL_VIEWER, int(model.local_viewer))
    gl.glLightModeli(gl.GL_LIGHT_MODEL_TWO_SIDE, int(model.two_sided))
    gl.glLightModeli(
        gl.GL_LIGHT_MODEL_COLOR_CONTROL,
        gl.GL_SEPARATE_SPECULAR_COLOR if model.separate_specular else gl.GL_SINGLE_COLOR,
    )
    gl.glMatrixMode(gl.GL_MODELVIEW)
    gl.glLoadIdentity()  # light positions below are already in eye space
    for i in range(MAX_LIGHTS):
        gl.glDisable(gl.GL_LIGHT0 + i)
    for i in range(len(lights)):
        light = gl.GL_LIGHT0 + i
        gl.glEnable(light)
        gl.glLightfv(light, gl.GL_POSITION, tuple(lights.position[i]))
        gl.glLightfv(light, gl.GL_AMBIENT, (*lights.ambient[i], 1.0))
        gl.glLightfv(light, gl.GL_DIFFUSE, (*lights.diffuse[i], 1.0))
        gl.glLightfv(light, gl.GL_SPECULAR, (*lights.specular[i], 1.0))
        kc, kl, kq = lights.attenuation[i]
        gl.glLightf(light, gl.GL_CONSTANT_ATTENUATION, kc)
        gl.glLightf(light, gl.GL_LINEAR_ATTENUATION, kl)
        gl.glLightf(light, gl.GL_QUADRATIC_ATTENUATION, kq)
        if np.isfinite(lights.cos_cutoff[i]):
            source = scene.lights[lights.source[i]]
            gl.glLightfv(light, gl.GL_SPOT_DIRECTION, tuple(lights.spot_direction[i]))
            gl.glLightf(light, gl.GL_SPOT_CUTOFF, source.cutoff)
            gl.glLightf(light, gl.GL_SPOT_EXPONENT, lights.spot_exponent[i])
        else:
            gl.glLightf(light, gl.GL_SPOT_CUTOFF, 180.0)
    gl.glMatrixMode(gl.GL_PROJECTION)
    gl.glLoadMatrixd(np.ascontiguousarray(scene.camera.projection.T))
    return len(lights)


def _set_material(gl, face, material) -> None:
    gl.glMaterialfv(face, gl.GL_AMBIENT, (*material.ambient, 1.0))
    gl.glMaterialfv(face, gl.GL_DIFFUSE, (*material.diffuse, material.opacity))
    gl.glMaterialfv(face, gl.GL_SPECULAR, (*material.specular, 1.0))
    gl.glMaterialfv(face, gl.GL_EMISSION, (*material.emission, 1.0))
    gl.glMaterialf(face, gl.GL_SHININESS, material.shininess)


class _MeshBuffers:
    """Each mesh's positions, normals (float32) and indices (uint32) in GPU buffer objects."""

    def __init__(self, gl: object, scene: Scene) -> None:
        self.gl = gl
        self.items = []
        for mesh in scene.meshes:
            ids = gl.glGenBuffers(3)
            arrays = (
                np.ascontiguousarray(mesh.positions, dtype=np.float32),
                np.ascontiguousarray(_mesh_normals(mesh), dtype=np.float32),
                np.ascontiguousarray(mesh.triangles, dtype=np.uint32),
            )
            for buffer, array, target in zip(
                ids, arrays, (gl.GL_ARRAY_BUFFER, gl.GL_ARRAY_BUFFER, gl.GL_ELEMENT_ARRAY_BUFFER), strict=True
            ):
                gl.glBindBuffer(target, buffer)
                gl.glBufferData(target, array.nbytes, array, gl.GL_STATIC_DRAW)
            self.items.append((mesh, ids, arrays[2].size))
        gl.glBindBuffer(gl.GL_ARRAY_BUFFER, 0)
        gl.glBindBuffer(gl.GL_ELEMENT_ARRAY_BUFFER, 0)

    def draw(self, scene: Scene) -> None:
        gl = self.gl
        gl.glEnableClientState(gl.GL_VERTEX_ARRAY)
        gl.glEnableClientState(gl.GL_NORMAL_ARRAY)
        for mesh, (vbo, nbo, ibo), count in self.items:
            _set_material(gl, gl.GL_FRONT_AND_BACK, mesh.material)
            if mesh.back_material is not None:
                _set_material(gl, gl.GL_BACK, mesh.back_material)
            gl.glMatrixMode(gl.GL_MODELVIEW)
            gl.glLoadMatrixd(np.ascontiguousarray((scene.camera.view @ mesh.transform).T))
            gl.glBindBuffer(gl.GL_ARRAY_BUFFER, vbo)
            gl.glVertexPointer(3, gl.GL_FLOAT, 0, None)
            gl.glBindBuffer(gl.GL_ARRAY_BUFFER, nbo)
            gl.glNormalPointer(gl.GL_FLOAT, 0, None)
            gl.glBindBuffer(gl.GL_ELEMENT_ARRAY_BUFFER, ibo)
            gl.glDrawElements(gl.GL_TRIANGLES, count, gl.GL_UNSIGNED_INT, None)
        gl.glBindBuffer(gl.GL_ARRAY_BUFFER, 0)
        gl.glBindBuffer(gl.GL_ELEMENT_ARRAY_BUFFER, 0)
        gl.glDisableClientState(gl.GL_VERTEX_ARRAY)
        gl.glDisableClientState(gl.GL_NORMAL_ARRAY)

    def delete(self) -> None:
        for _, ids, _ in self.items:
            self.gl.glDeleteBuffers(3, ids)


def render_fixed_function(scene: Scene, width: int, height: int, *, flat: bool = False) -> GLRender:
    """Render ``scene`` with OpenGL fixed-function lighting (``GL_SMOOTH``, or ``GL_FLAT`` with ``flat``).

    Meshes without normals get the same averaged vertex normals the renderer uses.
    Raises :class:`oracles.egl.EGLUnavailable` when no context can be created.
    """
    info = gl_context()
    from OpenGL import GL

    gl = GL

    fb = Framebuffer(gl, width, height)
    try:
        start = time.perf_counter()
        _set_state(gl, scene, flat=flat)
        buffers = _MeshBuffers(gl, scene)
        buffers.draw(scene)
        gl.glFinish()
        buffers.delete()
        seconds = time.perf_counter() - start
        return GLRender(fb.read(), seconds, info.renderer, depth=fb.read_depth())
    finally:
        fb.delete()


_PROGRAM: dict[str, int] = {}


def _program(gl) -> int:
    if "phong" in _PROGRAM:
        return _PROGRAM["phong"]
    program = compile_program(gl, _VERTEX_SHADER, _FRAGMENT_SHADER)
    _PROGRAM["phong"] = program
    return program


def render_glsl_phong(scene: Scene, width: int, height: int, *, repeats: int = 1) -> GLRender:
    """Render ``scene`` with the per-pixel Blinn-Phong GLSL program (same state as the fixed function).

    Geometry is uploaded once to buffer objects (float32 positions and normals). ``repeats``
    sets how many frames are drawn and timed after one untimed warm-up frame (shader
    variant compilation, upload); ``seconds`` is the mean per frame, including ``glFinish``.
    """
    info = gl_context()
    from OpenGL import GL

    gl = GL

    fb = Framebuffer(gl, width, height)
    try:
        program = _program(gl)
        gl.glUseProgram(program)
        n = _set_state(gl, scene, flat=False)
        gl.glUniform1i(gl.glGetUniformLocation(program, "n_lights"), n)
        gl.glUniform1i(gl.glGetUniformLocation(program, "local_viewer"), int(scene.light_model.local_viewer))
        gl.glUniform1i(gl.glGetUniformLocation(program, "two_sided"), int(scene.light_model.two_sided))
        buffers = _MeshBuffers(gl, scene)
        buffers.draw(scene)  # warm-up: shader variant compilation, buffer upload
        gl.glFinish()
        start, cpu_start = time.perf_counter(), time.process_time()
        for _ in range(max(repeats, 1)):
            gl.glClear(gl.GL_COLOR_BUFFER_BIT | gl.GL_DEPTH_BUFFER_BIT)
            buffers.draw(scene)
            gl.glFinish()
        seconds = (time.perf_counter() - start) / max(repeats, 1)
        cpu_seconds = (time.process_time() - cpu_start) / max(repeats, 1)
        buffers.delete()
        image = fb.read()
        gl.glUseProgram(0)
        return GLRender(image, seconds, info.renderer, cpu_seconds, fb.read_depth())
    finally:
        fb.delete()
