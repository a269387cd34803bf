"""Texture lookups at coordinates far outside [0, 1] (up to ±1e300), both engines.

Expected values come from the definitions (OpenGL 2.1 §3.8.7–3.8.8, module docstring of
``blinn_phong.model.texture``), evaluated by hand on a 4×2 image whose texel centres are exact
binary fractions:

* ``extend`` (``GL_CLAMP_TO_EDGE``): beyond the image, the edge texel on that side;
* ``clip``: transparent black outside [0, 1];
* ``repeat``: ``u mod 1``; every float64 with ``|u| ≥ 2^52`` is an integer, so ``u mod 1 = 0``:
  closest gives column 0, linear half column ``W − 1`` and half column 0 (``x = −0.5``).

The numpy lookup must give them without a RuntimeWarning (an unguarded ``floor(u·W)`` cast to
int64 overflows above ``2^63/W``: numpy warns and returns the minimum int64, i.e. the left edge;
numba's cast is silent), and the compiled texture stage (``engine="numba"``) must give the same
through a render of emissive quads, each with one constant texture coordinate.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.model.texture import Texture

W, H = 4, 2
# Row 0 at the TOP; distinct opaque texels.
IMAGE = np.array(
    [
        [[0.1, 0.0, 0.0, 1.0], [0.2, 0.0, 0.0, 1.0], [0.3, 0.0, 0.0, 1.0], [0.4, 0.0, 0.0, 1.0]],
        [[0.0, 0.5, 0.0, 1.0], [0.0, 0.6, 0.0, 1.0], [0.0, 0.7, 0.0, 1.0], [0.0, 0.8, 0.0, 1.0]],
    ],
    np.float32,
)
U0 = 0.5 / W  # centre of column 0: closest column 0, linear weight 0 on column 1 (exact)
V0 = 0.5 / H  # centre of the bottom row (j = 0)
HUGE = [1e30, -1e30, 1e300, -1e300, 2.0**63, -(2.0**63), 2.0**53 + 2.0, 1.7e308]


def texel(i: int, j: int) -> np.ndarray:
    """Texel of column ``i`` (from the left) and row ``j`` (from the bottom), float64."""
    return IMAGE[H - 1 - j, i].astype(np.float64)


def expected(u: float, v: float, interpolation: str, extension: str) -> np.ndarray:
    """The lookup by definition, for coordinates that are either a texel centre (U0, V0) or huge."""

    def axis(c: float, centre: float, n: int) -> list[tuple[int, float]]:
        """(index, weight) pairs along one axis."""
        if c == centre:
            return [(0, 1.0)]
        if extension == "extend":
            return [(n - 1 if c > 0 else 0, 1.0)]
        if extension == "clip":
            return []
        # repeat: |c| >= 2^52, so c mod 1 = 0
        return [(0, 1.0)] if interpolation == "closest" else [(n - 1, 0.5), (0, 0.5)]

    out = np.zeros(4)
    for i, wi in axis(u, U0, W):
        for j, wj in axis(v, V0, H):
            out += wi * wj * texel(i, j)
    return out


CASES = [(u, V0) for u in HUGE] + [(U0, v) for v in HUGE] + [(1e300, -1e300), (-1e30, 1e30)]
MODES = [(i, e) for i in ("closest", "linear") for e in ("repeat", "extend", "clip")]


@pytest.mark.parametrize(("interpolation", "extension"), MODES)
def test_lookup_far_outside_follows_the_definition(interpolation: str, extension: str) -> None:
    texture = Texture(IMAGE, interpolation=interpolation, extension=extension)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the int64 cast overflow warned (RuntimeWarning)
        got = texture.sample(np.array(CASES))
    want = np.array([expected(u, v, interpolation, extension) for u, v in CASES])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)


@pytest.mark.parametrize("interpolation", ["closest", "linear"])
def test_repeat_reduces_u_mod_1_exactly(interpolation: str) -> None:
    """Moderately large and tiny negative coordinates: ``u mod 1`` as Python's exact ``%`` gives it."""
    texture = Texture(IMAGE, interpolation=interpolation, extension="repeat")
    # 2^40 + 0.375 (float64 spacing 2^-12 there): u mod 1 = 0.375 → x = 1.5; the negative one
    # 0.625 → x = 2.5; -1e-20 mod 1 = 1 − 1e-20 → column W − 1 (x = 4 − 4e-20).
    us = [2.0**40 + 0.375, -(2.0**40) - 0.375, -1e-20]
    got = texture.sample(np.array([[u, V0] for u in us]))
    fractions = [u % 1.0 for u in us]  # Python's float % is exact
    assert fractions[:2] == [0.375, 0.625]
    if interpolation == "closest":
        want = [texel(1, 0), texel(2, 0), texel(W - 1, 0)]
    else:  # x − 0.5 = 1.0 and 2.0: exactly a texel centre; the last between column 3 and column 0
        want = [texel(1, 0), texel(2, 0), 0.5 * texel(W - 1, 0) + 0.5 * texel(0, 0)]
    np.testing.assert_allclose(got, np.array(want), rtol=0, atol=1e-15)


def constant_uv_quads(texture: Texture, cases: list[tuple[float, float]]) -> bp.Scene:
    """Quad k covers pixel k of an N × 1 frame; its four vertices all have uv = cases[k]."""
    meshes = []
    material = bp.Material(
        ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(1, 1, 1), base_color_texture=texture
    )
    for k, uv in enumerate(cases):
        pos = np.array([[k, -1, 0], [k + 1, -1, 0], [k + 1, 1, 0], [k, 1, 0]], float)
        meshes.append(
            bp.Mesh(pos, np.array([[0, 1, 2], [0, 2, 3]]), material=material, uv=np.tile(uv, (4, 1)))
        )
    n = len(cases)
    camera = bp.Camera(
        bp.look_at((n / 2, 0, 2), (n / 2, 0, 0)), bp.orthographic_matrix(-n / 2, n / 2, -0.5, 0.5, 0.5, 5)
    )
    return bp.Scene(meshes, [], camera, ambient=(0.0, 0.0, 0.0))


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize(("interpolation", "extension"), MODES)
def test_rendered_far_coordinates_in_both_engines(engine: str, interpolation: str, extension: str) -> None:
    if engine == "numba":
        pytest.importorskip("numba")
    texture = Texture(IMAGE, interpolation=interpolation, extension=extension)
    scene = constant_uv_quads(texture, CASES)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rgba = bp.render(scene, len(CASES), 1, engine=engine).rgba[0]
    # Emission 1, no lights: the pixel is the premultiplied texel. The interpolated uv is
    # Σ b_i·uv, equal to uv up to rounding: a linear weight of ~1e-16 may appear (float32 output).
    want = np.array([expected(u, v, interpolation, extension) for u, v in CASES])
    np.testing.assert_allclose(rgba, want, rtol=0, atol=1e-6)
