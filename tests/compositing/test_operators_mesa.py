"""The GL-realisable operators against real OpenGL: Mesa llvmpipe blending into an RGBA32F
framebuffer with the (Fa, Fb) names of the factor table as glBlendFunc factors and
FUNC_ADD; and ``composite`` against ``gl_blend(*gl_factors(op))`` (both paths agree)."""

from __future__ import annotations

import numpy as np
import pytest
from compositing_testdata import premultiplied_pixels

from compositing import ALL_OPERATORS, composite

REALISABLE = [name for name, spec in ALL_OPERATORS.items() if spec.gl_realisable]
PIXELS = 600


GL_ORACLE = "gl_blend"  # the gl fixture (tests/conftest.py)


def test_the_twelve_and_plus_are_realisable():
    assert REALISABLE == [*list(ALL_OPERATORS)[:12], "plus"]


@pytest.mark.mesa
def test_realisable_operators_match_mesa_rgba32f(gl):
    src = np.stack([premultiplied_pixels(PIXELS, 100 + i) for i in range(len(REALISABLE))])
    dst = np.stack([premultiplied_pixels(PIXELS, 200 + i) for i in range(len(REALISABLE))])
    states = [gl.BlendState(ALL_OPERATORS[op].fa, ALL_OPERATORS[op].fb) for op in REALISABLE]
    got_gl = gl.mesa_blend(src, dst, states, target="float32")
    for i, op in enumerate(REALISABLE):
        ours = composite(src[i], dst[i], op, engine="numpy")
        # float32 products and one sum, HDR values up to ~16: a few ulps at most.
        np.testing.assert_allclose(ours, got_gl[i], rtol=1e-6, atol=1e-6, err_msg=op)


@pytest.mark.parametrize("op", REALISABLE)
def test_composite_equals_gl_blend_with_gl_factors(op):
    gl = pytest.importorskip("compositing.gl_blend")
    a, b = premultiplied_pixels(500, 7), premultiplied_pixels(500, 8)
    sf, df = gl.gl_factors(op)
    np.testing.assert_allclose(composite(a, b, op), gl.gl_blend(a, b, sf, df), rtol=2.5e-7, atol=1e-7)
