"""Fixtures shared by every test folder.

Mesa llvmpipe through EGL is the OpenGL oracle of the ``*_vs_mesa`` and ``*_mesa`` tests:

* ``mesa_context`` starts the headless context once per process (:func:`oracles.egl.gl_context`)
  and skips the requesting test, with the reason, when EGL cannot start;
* ``gl`` is the oracle module a test module names in its ``GL_ORACLE`` constant (for example
  ``GL_ORACLE = "gl_lighting"`` gives :mod:`oracles.gl_lighting`), on a started context.
"""

from __future__ import annotations

import importlib
from types import ModuleType

import pytest

from oracles.egl import EGLUnavailable, GLInfo, gl_context


@pytest.fixture(scope="session")
def mesa_context() -> GLInfo:
    """The current Mesa OpenGL context's identification; skips when EGL cannot start."""
    try:
        return gl_context()
    except EGLUnavailable as exc:
        pytest.skip(f"Mesa EGL unavailable: {exc}")


@pytest.fixture(scope="module")
def gl(request: pytest.FixtureRequest, mesa_context: GLInfo) -> ModuleType:
    """The ``oracles`` module named by the requesting test module's ``GL_ORACLE``."""
    name = getattr(request.module, "GL_ORACLE", None)
    if not isinstance(name, str):
        raise TypeError(
            f"{request.module.__name__} uses the gl fixture but defines no GL_ORACLE naming an "
            f"oracles module (e.g. GL_ORACLE = 'gl_lighting'); got {name!r}"
        )
    return importlib.import_module(f"oracles.{name}")
