"""Run OpenGL's blend stage on Mesa llvmpipe for a batch of blend states.

This is the reference :func:`compositing.gl_blend` is tested against: real GL blending,
not our arithmetic. For every blend state the destination pixels are stored in a tile of
a framebuffer object (RGBA8 or RGBA32F), the source pixels are drawn over that tile as
the fragment colour of one full-tile triangle with the state's ``glBlendFuncSeparate``,
``glBlendEquationSeparate`` and ``glBlendColor``, and the whole framebuffer is read back
once. Dithering is off, so an RGBA8 store is a plain conversion.

The fragment colour comes from an RGBA32F texture read with ``texelFetch`` at the
fragment's own window position, so the shader hands the blender the exact float32 source
values; an RGBA8 framebuffer then clamps and converts them itself (the default
``GL_CLAMP_FRAGMENT_COLOR = GL_FIXED_ONLY`` of the compatibility profile clamps for
fixed-point buffers only).

Pixels are plain lists here, not images: ``src`` and ``dst`` have shape
``(n_states, n_pixels, 4)`` and the result has the same shape. Internally each list is laid
out in a square tile in GL's row order (row 0 at the bottom) for upload and taken back in
the same order after ``glReadPixels``, so no flip is involved.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from oracles.egl import gl_context
from oracles.gl_common import compile_program

__all__ = ["MESA_TARGETS", "BlendState", "mesa_accepts_blend_func", "mesa_blend"]

#: Framebuffer formats, named as :func:`compositing.gl_blend`'s ``target``.
MESA_TARGETS = ("float32", "unorm8")

_VERTEX_SHADER = """
#version 330 core
void main() {
    // One triangle covering the viewport: (-1,-1), (3,-1), (-1,3).
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(p, 0.0, 1.0);
}
"""

_FRAGMENT_SHADER = """
#version 330 core
uniform sampler2D source;
out vec4 colour;
void main() {
    colour = texelFetch(source, ivec2(gl_FragCoord.xy), 0);
}
"""


@dataclass(frozen=True)
class BlendState:
    """One OpenGL blend state; names as GL without the ``GL_`` prefix. ``None`` alpha fields copy RGB."""

    src_factor: str
    dst_factor: str
    equation: str = "FUNC_ADD"
    src_factor_alpha: str | None = None
    dst_factor_alpha: str | None = None
    equation_alpha: str | None = None
    constant: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    def gl_enums(self) -> tuple[int, int, int, int, int, int]:
        """(srcRGB, dstRGB, srcAlpha, dstAlpha, modeRGB, modeAlpha) as GL enum values."""
        from OpenGL import GL

        names = (
            self.src_factor,
            self.dst_factor,
            self.src_factor_alpha or self.src_factor,
            self.dst_factor_alpha or self.dst_factor,
            self.equation,
            self.equation_alpha or self.equation,
        )
        return tuple(getattr(GL, "GL_" + n.upper()) for n in names)  # type: ignore[return-value]


def _tiles(values: np.ndarray, tile: int, cols: int, rows: int) -> np.ndarray:
    """Lay (n_states, n_pixels, 4) out as a (rows·tile, cols·tile, 4) texture in GL row order."""
    n_states, n_pixels, _ = values.shape
    padded = np.zeros((rows * cols, tile * tile, 4), dtype=values.dtype)
    padded[:n_states, :n_pixels] = values
    grid = padded.reshape(rows, cols, tile, tile, 4).transpose(0, 2, 1, 3, 4)
    return np.ascontiguousarray(grid.reshape(rows * tile, cols * tile, 4))


def _untile(image: np.ndarray, tile: int, cols: int, rows: int, n_states: int, n_pixels: int) -> np.ndarray:
    """Inverse of :func:`_tiles`."""
    grid = image.reshape(rows, tile, cols, tile, 4).transpose(0, 2, 1, 3, 4)
    return grid.reshape(rows * cols, tile * tile, 4)[:n_states, :n_pixels]


def mesa_blend(
    src: np.ndarray, dst: np.ndarray, states: Sequence[BlendState], target: str = "float32"
) -> np.ndarray:
    """Blend ``src`` onto ``dst`` with Mesa's OpenGL, one draw per blend state.

    Args:
        src: Fragment colours, float32-convertible, shape ``(n_states, n_pixels, 4)``; any
            finite values (an RGBA8 framebuffer clamps them itself).
        dst: Framebuffer contents before the draw, same shape: float32 for ``"float32"``
            (stored in an RGBA32F buffer), uint8 bytes for ``"unorm8"`` (an RGBA8 buffer).
        states: One :class:`BlendState` per row of ``src``/``dst``.
        target: ``"float32"`` (GL_RGBA32F) or ``"unorm8"`` (GL_RGBA8).

    Returns:
        The framebuffer after blending, shape ``(n_states, n_pixels, 4)``: float32 values for
        ``"float32"``, the uint8 bytes for ``"unorm8"``.

    Raises:
        oracles.egl.EGLUnavailable: no GL context can be created.
        OpenGL.error.GLError: Mesa rejects a blend state (e.g. a factor illegal as dfactor).
    """
    if target not in MESA_TARGETS:
        raise ValueError(f"target must be one of {MESA_TARGETS}, got {target!r}")
    src = np.asarray(src, dtype=np.float32)
    dst = np.asarray(dst)
    if src.ndim != 3 or src.shape[-1] != 4 or src.shape != dst.shape or src.shape[0] != len(states):
        raise ValueError(
            f"src and dst must both have shape (n_states={len(states)}, n_pixels, 4), "
            f"got src {src.shape}, dst {dst.shape}"
        )
    want_dtype = np.uint8 if target == "unorm8" else np.float32
    if dst.dtype != want_dtype:
        raise TypeError(f"dst for target {target!r} must be {np.dtype(want_dtype)}, got {dst.dtype}")

    gl_context()
    from OpenGL import GL

    n_states, n_pixels, _ = src.shape
    tile = max(1, math.ceil(math.sqrt(n_pixels)))
    max_size = int(GL.glGetIntegerv(GL.GL_MAX_TEXTURE_SIZE))
    cols = max(1, min(math.ceil(math.sqrt(n_states)), max_size // tile))
    rows = math.ceil(n_states / cols)
    width, height = cols * tile, rows * tile
    if height > max_size:
        raise ValueError(f"{n_states} states of {n_pixels} pixels do not fit a {max_size}² framebuffer")

    internal, pixel_type = (
        (GL.GL_RGBA8, GL.GL_UNSIGNED_BYTE) if target == "unorm8" else (GL.GL_RGBA32F, GL.GL_FLOAT)
    )
    textures = GL.glGenTextures(2)
    colour_tex, source_tex = int(textures[0]), int(textures[1])
    fbo = GL.glGenFramebuffers(1)
    vao = GL.glGenVertexArrays(1)
    program = compile_program(GL, _VERTEX_SHADER, _FRAGMENT_SHADER)
    GL.glPushAttrib(GL.GL_ALL_ATTRIB_BITS)
    GL.glPushClientAttrib(GL.GL_CLIENT_ALL_ATTRIB_BITS)
    try:
        for tex, fmt, typ, data in (
            (colour_tex, internal, pixel_type, _tiles(dst, tile, cols, rows)),
            (source_tex, GL.GL_RGBA32F, GL.GL_FLOAT, _tiles(src, tile, cols, rows)),
        ):
            GL.glBindTexture(GL.GL_TEXTURE_2D, tex)
            GL.glTexParameteri(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_MIN_FILTER, GL.GL_NEAREST)
            GL.glTexParameteri(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_MAG_FILTER, GL.GL_NEAREST)
            GL.glPixelStorei(GL.GL_UNPACK_ALIGNMENT, 1)
            GL.glTexImage2D(GL.GL_TEXTURE_2D, 0, fmt, width, height, 0, GL.GL_RGBA, typ, data)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fbo)
        GL.glFramebufferTexture2D(GL.GL_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_TEXTURE_2D, colour_tex, 0)
        status = GL.glCheckFramebufferStatus(GL.GL_FRAMEBUFFER)
        if status != GL.GL_FRAMEBUFFER_COMPLETE:
            raise RuntimeError(f"framebuffer incomplete: 0x{int(status):x}")
        GL.glDrawBuffers(1, [GL.GL_COLOR_ATTACHMENT0])

        GL.glUseProgram(program)
        GL.glActiveTexture(GL.GL_TEXTURE0)
        GL.glBindTexture(GL.GL_TEXTURE_2D, source_tex)
        GL.glUniform1i(GL.glGetUniformLocation(program, "source"), 0)
        GL.glBindVertexArray(vao)
        # Everything between the fragment colour and the store, in a known state (pushed/popped,
        # so other users of the shared context are not affected).
        for cap in (
            GL.GL_DITHER,
            GL.GL_DEPTH_TEST,
            GL.GL_STENCIL_TEST,
            GL.GL_CULL_FACE,
            GL.GL_COLOR_LOGIC_OP,
            GL.GL_SAMPLE_ALPHA_TO_COVERAGE,
            GL.GL_RASTERIZER_DISCARD,
            GL.GL_FRAMEBUFFER_SRGB,
        ):
            GL.glDisable(cap)
        GL.glColorMask(GL.GL_TRUE, GL.GL_TRUE, GL.GL_TRUE, GL.GL_TRUE)
        GL.glPolygonMode(GL.GL_FRONT_AND_BACK, GL.GL_FILL)
        GL.glClampColor(GL.GL_CLAMP_FRAGMENT_COLOR, GL.GL_FIXED_ONLY)
        GL.glClampColor(GL.GL_CLAMP_READ_COLOR, GL.GL_FALSE)
        GL.glEnable(GL.GL_BLEND)
        GL.glEnable(GL.GL_SCISSOR_TEST)
        for index, state in enumerate(states):
            x, y = (index % cols) * tile, (index // cols) * tile
            GL.glViewport(x, y, tile, tile)
            GL.glScissor(x, y, tile, tile)
            sf, df, sfa, dfa, eq, eqa = state.gl_enums()
            GL.glBlendFuncSeparate(sf, df, sfa, dfa)
            GL.glBlendEquationSeparate(eq, eqa)
            GL.glBlendColor(*(float(v) for v in state.constant))
            GL.glDrawArrays(GL.GL_TRIANGLES, 0, 3)
        GL.glFinish()
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        raw = GL.glReadPixels(0, 0, width, height, GL.GL_RGBA, pixel_type)
    finally:
        GL.glPopClientAttrib()
        GL.glPopAttrib()
        GL.glUseProgram(0)
        GL.glBindVertexArray(0)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        GL.glDeleteVertexArrays(1, [vao])
        GL.glDeleteFramebuffers(1, [fbo])
        GL.glDeleteTextures([colour_tex, source_tex])
        GL.glDeleteProgram(program)
    image = np.frombuffer(raw, dtype=want_dtype).reshape(height, width, 4)
    return _untile(image, tile, cols, rows, n_states, n_pixels).copy()


def mesa_accepts_blend_func(src_factor: str, dst_factor: str) -> bool:
    """Whether Mesa's ``glBlendFunc`` accepts the pair (no GL_INVALID_ENUM)."""
    gl_context()
    from OpenGL import GL
    from OpenGL.error import GLError

    while GL.glGetError() != GL.GL_NO_ERROR:
        pass
    try:
        GL.glBlendFunc(getattr(GL, "GL_" + src_factor.upper()), getattr(GL, "GL_" + dst_factor.upper()))
    except GLError:
        return False
    finally:
        GL.glBlendFunc(GL.GL_ONE, GL.GL_ZERO)
    return GL.glGetError() == GL.GL_NO_ERROR
