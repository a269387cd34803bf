"""A headless OpenGL context on Mesa llvmpipe through EGL surfaceless.

``PYOPENGL_PLATFORM=egl`` and ``EGL_PLATFORM=surfaceless`` must be set before
PyOpenGL is first imported; :func:`gl_context` does that and then creates a
compatibility-profile context with no config and no surface
(EGL_KHR_no_config_context, EGL_KHR_surfaceless_context), so all drawing goes
to framebuffer objects the caller creates.

Mesa docs on ``EGL_PLATFORM``: https://docs.mesa3d.org/envvars.html ;
EGL_MESA_platform_surfaceless:
https://registry.khronos.org/EGL/extensions/MESA/EGL_MESA_platform_surfaceless.txt
"""

from __future__ import annotations

import ctypes
import functools
import os
import sys
from dataclasses import dataclass

__all__ = ["EGLUnavailable", "GLInfo", "gl_context"]


class EGLUnavailable(RuntimeError):
    """Raised when no EGL/OpenGL context can be created; the message says why."""


@dataclass(frozen=True)
class GLInfo:
    """Strings identifying the OpenGL implementation behind the context."""

    renderer: str
    version: str
    vendor: str


@functools.lru_cache(maxsize=1)
def gl_context() -> GLInfo:
    """Create (once per process) and make current a Mesa OpenGL compatibility context.

    Returns the renderer/version strings. Raises :class:`EGLUnavailable` with the
    reason when EGL cannot start (no libEGL, no display, context refused). The
    context stays current on the calling thread for the life of the process.
    """
    if "OpenGL" in sys.modules and os.environ.get("PYOPENGL_PLATFORM") != "egl":
        raise EGLUnavailable("PyOpenGL was imported before PYOPENGL_PLATFORM=egl could be set")
    os.environ["PYOPENGL_PLATFORM"] = "egl"
    os.environ.setdefault("EGL_PLATFORM", "surfaceless")
    try:
        from OpenGL import EGL, GL
    except Exception as exc:  # ImportError, or a missing libEGL raised at import
        raise EGLUnavailable(f"PyOpenGL with EGL could not load: {exc}") from exc

    try:
        display = EGL.eglGetDisplay(EGL.EGL_DEFAULT_DISPLAY)
        major, minor = EGL.EGLint(), EGL.EGLint()
        if not EGL.eglInitialize(display, ctypes.pointer(major), ctypes.pointer(minor)):
            raise EGLUnavailable("eglInitialize failed (no EGL display)")
        if not EGL.eglBindAPI(EGL.EGL_OPENGL_API):
            raise EGLUnavailable("eglBindAPI(EGL_OPENGL_API) failed")
        context = EGL.eglCreateContext(display, EGL.EGLConfig(), EGL.EGL_NO_CONTEXT, None)
        if not context:
            raise EGLUnavailable("eglCreateContext without a config failed")
        if not EGL.eglMakeCurrent(display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, context):
            raise EGLUnavailable("eglMakeCurrent without a surface failed")
        info = GLInfo(
            renderer=GL.glGetString(GL.GL_RENDERER).decode(),
            version=GL.glGetString(GL.GL_VERSION).decode(),
            vendor=GL.glGetString(GL.GL_VENDOR).decode(),
        )
    except EGLUnavailable:
        raise
    except Exception as exc:
        raise EGLUnavailable(f"EGL surfaceless context could not start: {exc}") from exc
    return info
