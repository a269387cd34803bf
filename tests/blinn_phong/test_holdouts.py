"""Holdouts (``Mesh.holdout``) against closed forms, through every transparency method.

An orthographic camera over a W×H window; an emission-only quad fills it at z = −3 (its colour is
exactly ``e``, OpenGL 2.1 §2.14.1 with zero ambient, diffuse and specular), a holdout rectangle
lies in front of it at z = −2. With k×k ordered samples at ``((i + ½)/k, (j + ½)/k)`` a pixel's
expected alpha is ``1 − n/k²``, ``n`` the samples inside the holdout (counted here from the
rectangle's edges), and its colour ``e·alpha`` (premultiplied): Porter & Duff's ``bg out holdout``.
The edges lie at ``.55``/``.45`` of a pixel, off every sample at k = 1 and k = 4, so a corner
pixel has 2×2 = 4 of 16 samples held out (alpha 12/16) and an edge pixel 8 of 16.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from tests.meshes import rectangle

W, H = 9, 7
E = (0.2, 0.45, 0.7)  # the background's emission
PANE_E = (0.9, 0.3, 0.1)  # the transparent pane's emission
HOLD = (2.55, 5.45, 1.55, 4.45)  # x0, x1, y0, y1 (window units, y up)
METHODS = [
    "zbuffer",
    "a_buffer",
    "depth_peeling",
    "sort_objects",
    "sort_triangles",
    "draw_last",
    "weighted_blended",
]


def _emitter(emission: tuple[float, float, float], opacity: float = 1.0) -> bp.Material:
    return bp.Material(
        ambient=(0, 0, 0), diffuse=(0, 0, 0), specular=(0, 0, 0), emission=emission, opacity=opacity
    )


def _scene(*extra: bp.Mesh) -> bp.Scene:
    back = rectangle(-1, W + 1, -1, H + 1, -3.0, _emitter(E))
    hold = rectangle(*HOLD, -2.0, _emitter((1.0, 1.0, 1.0)), holdout=True)
    return bp.Scene(
        [back, hold, *extra], [], bp.Camera.orthographic(0, W, 0, H, 0.1, 10.0), ambient=(0, 0, 0)
    )


def _inside_fraction(rect: tuple[float, float, float, float], k: int) -> np.ndarray:
    """(H, W) fraction of each pixel's k×k samples inside ``rect`` (row 0 at the top)."""
    x0, x1, y0, y1 = rect
    offsets = (np.arange(k) + 0.5) / k
    out = np.zeros((H, W))
    for row in range(H):
        y = H - 1 - row  # the pixel's bottom edge in window units
        ys = y + offsets
        for x in range(W):
            xs = x + offsets
            out[row, x] = (
                np.count_nonzero((xs > x0) & (xs < x1)) * np.count_nonzero((ys > y0) & (ys < y1)) / k**2
            )
    return out


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize("samples", [1, 4])
@pytest.mark.parametrize("method", METHODS)
def test_holdout_in_front_of_an_emitter(method: str, samples: int, engine: str) -> None:
    result = bp.render(_scene(), W, H, samples=samples, engine=engine, transparency=method, shadows="none")
    held = _inside_fraction(HOLD, samples)
    alpha = 1.0 - held
    np.testing.assert_allclose(result.rgba[..., 3], alpha, rtol=0, atol=1e-6)
    np.testing.assert_allclose(result.rgba[..., :3], alpha[..., None] * np.asarray(E), rtol=0, atol=1e-6)
    if samples == 4:
        assert held[H - 1 - 1, 2] == 4 / 16 and result.rgba[H - 1 - 1, 2, 3] == np.float32(12 / 16)
    for name in ("ambient", "diffuse", "specular"):
        # the passes are weighted by alpha: only the emitter's share remains (emission is in "ambient")
        assert not result.passes[name][held == 1.0].any()


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize("method", METHODS[1:])
def test_transparent_pane_over_a_holdout_and_one_behind_it(method: str, engine: str) -> None:
    """A pane of opacity 0.4 in front of the holdout gives ``(0.4·e_p, 0.4)`` there (``over`` transparent
    black) and ``0.4·e_p + 0.6·e`` beside it; a pane behind the holdout is hidden."""
    front = rectangle(1.2, 7.8, 2.2, 3.8, -1.0, _emitter(PANE_E, 0.4))
    behind = rectangle(3.2, 4.8, 0.2, 6.8, -2.5, _emitter((0.0, 1.0, 0.0), 0.5))
    result = bp.render(_scene(front, behind), W, H, engine=engine, transparency=method, shadows="none")
    held = _inside_fraction(HOLD, 1)
    pane = _inside_fraction((1.2, 7.8, 2.2, 3.8), 1)
    behind_cover = _inside_fraction((3.2, 4.8, 0.2, 6.8), 1)
    e, p = np.asarray(E), np.asarray(PANE_E)
    expected = np.zeros((H, W, 4))
    for row in range(H):
        for x in range(W):
            if held[row, x]:
                base = np.zeros(4)  # the holdout: transparent black, the green pane behind it hidden
            elif behind_cover[row, x]:
                base = np.r_[0.5 * np.array([0.0, 1.0, 0.0]) + 0.5 * e, 1.0]
            else:
                base = np.r_[e, 1.0]
            if pane[row, x]:
                base = np.r_[0.4 * p, 0.4] + 0.6 * base
            expected[row, x] = base
    assert held.any() and (held * pane).any() and (behind_cover * (1 - held)).any()
    np.testing.assert_allclose(result.rgba, expected, rtol=0, atol=2e-6)


def test_holdout_with_a_transparent_material_is_opaque() -> None:
    glassy = rectangle(*HOLD, -2.0, _emitter((1.0, 1.0, 1.0), opacity=0.3), holdout=True)
    back = rectangle(-1, W + 1, -1, H + 1, -3.0, _emitter(E))
    scene = bp.Scene([back, glassy], [], bp.Camera.orthographic(0, W, 0, H, 0.1, 10.0), ambient=(0, 0, 0))
    result = bp.render(scene, W, H, transparency="a_buffer", shadows="none")
    held = _inside_fraction(HOLD, 1) == 1.0
    assert held.any()
    assert not result.rgba[held].any()


def test_holdout_flag_is_checked() -> None:
    with pytest.raises(TypeError, match=r"Mesh\.holdout"):
        rectangle(0, 1, 0, 1, -1.0, _emitter(E), holdout="yes")


def test_world_goes_behind_a_transparent_pane_but_not_behind_the_holdout() -> None:
    """A half-transparent pane over part of a holdout: with the world composited behind (Film →
    Transparent off, :mod:`blinn_phong.frame.background`), each pixel is
    ``pane + (1 − α_pane)·(0 where held out, else the world)`` (``over``; Cycles: a path through
    the pane that meets a holdout adds its throughput to the holdout, not the world's colour), with
    the pane's colour from a render of the pane alone and the held-out share in closed form."""
    from blinn_phong.frame.background import holdout_coverage, holdout_request, world_behind

    camera = bp.Camera.orthographic(0, W, 0, H, 0.1, 10.0)
    hold = rectangle(*HOLD, -2.0, _emitter((1.0, 1.0, 1.0)), holdout=True)
    pane = rectangle(4.0, W + 1, -1, H + 1, -1.0, _emitter((0.9, 0.3, 0.1), 0.5))
    world = np.array([0.05, 0.1, 0.2, 1.0], np.float32)
    alone = bp.render(
        bp.Scene([pane], [], camera, ambient=(0, 0, 0)), W, H, transparency="a_buffer", shadows="none"
    ).rgba.astype(np.float64)
    held = _inside_fraction(HOLD, 1)[..., None]
    expected = alone + (1.0 - alone[..., 3:]) * (1.0 - held) * world
    assert 0 < alone[0, -1, 3] < 1 and held.any() and (held[..., 0] * alone[..., 3] > 0).any()
    # no Cryptomatte asked for; the object layer (a free layer measures); every layer (the object
    # layer's IDs of the holdout measure)
    every = bp.Cryptomatte({k: ["Hold", "Pane"] for k in ("object", "material", "asset")}, 6)
    for asked in (None, bp.Cryptomatte({"object": ["Hold", "Pane"]}, 6), every):
        scene = bp.Scene([hold, pane], [], camera, ambient=(0, 0, 0))
        request = holdout_request(scene.meshes, asked)
        result = bp.render(scene, W, H, transparency="a_buffer", shadows="none", cryptomatte=request.request)
        held_coverage = holdout_coverage(result.passes, request)
        got = world_behind(result.rgba, world, held_coverage)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6)
        crypto = [p for p in result.passes if p.startswith("Crypto")]
        if asked is None:
            assert crypto == []  # the measurement's own passes are removed
        elif asked is every:
            assert len(crypto) == 9  # all kept
        else:
            assert sorted(crypto) == ["CryptoObject00", "CryptoObject01", "CryptoObject02"]
