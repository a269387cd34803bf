"""OpenGL helpers shared by the Mesa oracles: shader programs, framebuffers, readback, geometry.

Every function takes the PyOpenGL ``GL`` module as ``gl`` (imported lazily by the caller
after :func:`oracles.egl.gl_context`), so importing this module does not import OpenGL.
Readback follows the project convention: row 0 at the TOP (OpenGL stores rows bottom-up,
OpenGL 2.1 §4.3.2), so every image read here is flipped once.

Used only by tests and benchmarks.
"""

from __future__ import annotations

import numpy as np

from blinn_phong.model.scene import Scene

__all__ = [
    "Framebuffer",
    "blinn_phong_main",
    "compile_program",
    "read_pixels",
    "to_unorm8",
    "world_triangles",
]


def to_unorm8(rgba: np.ndarray) -> np.ndarray:
    """OpenGL's float -> UNORM8 conversion (round to nearest), as llvmpipe does; int64."""
    return np.floor(np.clip(rgba, 0.0, 1.0) * 255.0 + 0.5).astype(np.int64)


def compile_program(gl, vertex_source: str, fragment_source: str) -> int:
    """Compile and link a GLSL program from vertex and fragment shader sources; returns its name.

    Raises ``RuntimeError`` with the driver's info log when compiling or linking fails.
    """
    program = gl.glCreateProgram()
    for kind, source in ((gl.GL_VERTEX_SHADER, vertex_source), (gl.GL_FRAGMENT_SHADER, fragment_source)):
        shader = gl.glCreateShader(kind)
        gl.glShaderSource(shader, source)
        gl.glCompileShader(shader)
        if not gl.glGetShaderiv(shader, gl.GL_COMPILE_STATUS):
            raise RuntimeError(f"GLSL compile failed: {gl.glGetShaderInfoLog(shader).decode()}")
        gl.glAttachShader(program, shader)
        gl.glDeleteShader(shader)  # freed with the program
    gl.glLinkProgram(program)
    if not gl.glGetProgramiv(program, gl.GL_LINK_STATUS):
        raise RuntimeError(f"GLSL link failed: {gl.glGetProgramInfoLog(program).decode()}")
    return program


def read_pixels(
    gl, width: int, height: int, fmt: int, pixel_type: int, dtype: type, channels: int = 0
) -> np.ndarray:
    """``glReadPixels`` of the bound read framebuffer, tightly packed, row 0 at the top.

    Returns a new (H, W) array, or (H, W, ``channels``) when ``channels`` > 0, of ``dtype``.
    """
    gl.glPixelStorei(gl.GL_PACK_ALIGNMENT, 1)
    data = gl.glReadPixels(0, 0, width, height, fmt, pixel_type)
    shape = (height, width, channels) if channels else (height, width)
    return np.frombuffer(data, dtype).reshape(shape)[::-1].copy()


class Framebuffer:
    """An RGBA8 colour + depth framebuffer object of the given size, bound for drawing.

    The depth attachment is ``GL_DEPTH_COMPONENT24``, or ``GL_DEPTH24_STENCIL8`` with
    ``stencil``. The viewport is set to the whole framebuffer. Raises ``RuntimeError``
    when the framebuffer is incomplete.
    """

    def __init__(self, gl: object, width: int, height: int, *, stencil: bool = False) -> None:
        self.gl = gl
        self.fbo = gl.glGenFramebuffers(1)
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, self.fbo)
        self.rbs = gl.glGenRenderbuffers(2)
        gl.glBindRenderbuffer(gl.GL_RENDERBUFFER, self.rbs[0])
        gl.glRenderbufferStorage(gl.GL_RENDERBUFFER, gl.GL_RGBA8, width, height)
        gl.glFramebufferRenderbuffer(
            gl.GL_FRAMEBUFFER, gl.GL_COLOR_ATTACHMENT0, gl.GL_RENDERBUFFER, self.rbs[0]
        )
        depth_format, attachment = (
            (gl.GL_DEPTH24_STENCIL8, gl.GL_DEPTH_STENCIL_ATTACHMENT)
            if stencil
            else (gl.GL_DEPTH_COMPONENT24, gl.GL_DEPTH_ATTACHMENT)
        )
        gl.glBindRenderbuffer(gl.GL_RENDERBUFFER, self.rbs[1])
        gl.glRenderbufferStorage(gl.GL_RENDERBUFFER, depth_format, width, height)
        gl.glFramebufferRenderbuffer(gl.GL_FRAMEBUFFER, attachment, gl.GL_RENDERBUFFER, self.rbs[1])
        status = gl.glCheckFramebufferStatus(gl.GL_FRAMEBUFFER)
        if status != gl.GL_FRAMEBUFFER_COMPLETE:
            raise RuntimeError(f"framebuffer incomplete: status 0x{int(status):x}")
        gl.glViewport(0, 0, width, height)
        self.width, self.height = width, height

    def read(self) -> np.ndarray:
        """The colour buffer: uint8 (H, W, 4), row 0 at the top."""
        gl = self.gl
        return read_pixels(gl, self.width, self.height, gl.GL_RGBA, gl.GL_UNSIGNED_BYTE, np.uint8, 4)

    def read_depth(self) -> np.ndarray:
        """The depth buffer: float32 (H, W) window depth in [0, 1], row 0 at the top."""
        gl = self.gl
        return read_pixels(gl, self.width, self.height, gl.GL_DEPTH_COMPONENT, gl.GL_FLOAT, np.float32)

    def read_stencil(self) -> np.ndarray:
        """The stencil buffer: uint8 (H, W), row 0 at the top."""
        gl = self.gl
        return read_pixels(gl, self.width, self.height, gl.GL_STENCIL_INDEX, gl.GL_UNSIGNED_BYTE, np.uint8)

    def delete(self) -> None:
        """Bind the default framebuffer and delete this one with its renderbuffers."""
        self.gl.glBindFramebuffer(self.gl.GL_FRAMEBUFFER, 0)
        self.gl.glDeleteRenderbuffers(2, self.rbs)
        self.gl.glDeleteFramebuffers(1, [self.fbo])


def world_triangles(scene: Scene) -> np.ndarray:
    """Every mesh's triangles in world space: (n, 3, 3) float64, meshes in scene order."""
    parts = [
        (np.c_[m.positions, np.ones(len(m.positions))] @ m.transform.T)[:, :3][m.triangles]
        for m in scene.meshes
    ]
    return np.concatenate(parts)


# The OpenGL 2.1 §2.14.1 lighting equation per fragment (Blinn half vector), every light's state
# read from the built-in uniforms. ``@VIS@`` marks where a per-light visibility factor goes.
_PHONG_MAIN = """void main() {
    bool front = gl_FrontFacing || !two_sided;
    vec3 n = normalize(v_normal);
    if (!front) n = -n;
    vec4 m_ambient = front ? gl_FrontMaterial.ambient : gl_BackMaterial.ambient;
    vec4 m_diffuse = front ? gl_FrontMaterial.diffuse : gl_BackMaterial.diffuse;
    vec4 m_specular = front ? gl_FrontMaterial.specular : gl_BackMaterial.specular;
    float shininess = front ? gl_FrontMaterial.shininess : gl_BackMaterial.shininess;
    vec3 scene = front ? gl_FrontLightModelProduct.sceneColor.rgb : gl_BackLightModelProduct.sceneColor.rgb;
    vec3 v = local_viewer ? normalize(-v_position) : vec3(0.0, 0.0, 1.0);
    vec3 ambient = scene;
    vec3 diffuse = vec3(0.0);
    vec3 specular = vec3(0.0);
    for (int i = 0; i < 8; i++) {
        if (i >= n_lights) break;
        vec4 p = gl_LightSource[i].position;
        vec3 l;
        float att = 1.0;
        if (p.w != 0.0) {
            vec3 d = p.xyz / p.w - v_position;
            float dist = length(d);
            l = d / dist;
            att = 1.0 / (gl_LightSource[i].constantAttenuation + gl_LightSource[i].linearAttenuation * dist
                         + gl_LightSource[i].quadraticAttenuation * dist * dist);
        } else {
            l = normalize(p.xyz);
        }
        if (gl_LightSource[i].spotCutoff != 180.0) {
            float c = dot(-l, normalize(gl_LightSource[i].spotDirection));
            float cone = pow(max(c, 0.0), gl_LightSource[i].spotExponent);
            att *= (c >= gl_LightSource[i].spotCosCutoff) ? cone : 0.0;
        }
        ambient += att * m_ambient.rgb * gl_LightSource[i].ambient.rgb;
        float ndl = dot(n, l);
        if (ndl > 0.0) {
@VIS_DECL@            diffuse += @VIS@att * ndl * m_diffuse.rgb * gl_LightSource[i].diffuse.rgb;
            float nh = max(dot(n, normalize(l + v)), 0.0);
            specular += @VIS@att * pow(nh, shininess) * m_specular.rgb * gl_LightSource[i].specular.rgb;
        }
    }
    gl_FragColor = vec4(ambient + diffuse + specular, m_diffuse.a);
}
"""


def blinn_phong_main(visibility: str | None = None) -> str:
    """GLSL ``main()`` of the per-pixel Blinn-Phong fragment shader (OpenGL 2.1 §2.14.1).

    Expects the uniforms ``n_lights``, ``local_viewer``, ``two_sided`` and the eye-space inputs
    ``v_position``, ``v_normal``. With ``visibility`` (a GLSL expression of the light index
    ``i``, e.g. ``"visibility(i)"``), each light's diffuse and specular terms are multiplied by it.
    """
    if visibility is None:
        return _PHONG_MAIN.replace("@VIS_DECL@", "").replace("@VIS@", "")
    decl = f"            float vis = {visibility};\n"
    return _PHONG_MAIN.replace("@VIS_DECL@", decl).replace("@VIS@", "vis * ")
