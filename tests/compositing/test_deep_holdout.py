"""Holdouts in the renderer's deep output (``render(..., deep=True)``) against closed forms.

The scene of ``tests/blinn_phong/test_holdouts.py``: an orthographic camera over a W×H window, an
emission-only quad of colour ``E`` filling it at z = −3 and a holdout rectangle in front of it at
z = −2 whose edges lie off every sample. With one sample per pixel each pixel is held out or not;
with k×k samples ``held`` (counted from the rectangle's edges) is the held fraction.

A holdout's deep samples are ``(0, 0, 0, coverage)`` (the OpenEXR/Nuke deep-holdout convention),
so (Porter & Duff; OpenEXR "Interpreting Deep Pixels" for flatten and merge):

* flattening the deep frame gives the flat frame's colour (alpha 0 where held out in the flat
  frame) and the flat frame's alpha plus the holdout's visible coverage: ``1`` everywhere here;
* the holdout samples alone flatten to ``(0, 0, 0, held)``;
* a second deep image ``X`` behind the holdout (a half-transparent emitter at z = −2.5, rendered
  on its own) deep-merged with the frame is cut where the holdout is:
  ``flatten(merge(deep, X)) = (0, 0, 0, 1)`` there, ``X over E`` elsewhere (``over``:
  ``x + (1 − αx)·e``); what ``X`` contributes to that merge, ``flatten(holdout(X, deep))``, is
  ``X out holdout`` (0 where held out); and the flat render of both scenes together (the holdout
  transparent, alpha 0, as in Cycles) is the merge less the holdout's own alpha.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from compositing.deep import flatten, holdout, merge
from tests.blinn_phong.test_holdouts import HOLD, H, W, _emitter, _inside_fraction, _scene
from tests.meshes import rectangle

X_E = (0.1, 0.8, 0.3)
X_OPACITY = 0.6


def _x_quad() -> bp.Mesh:
    return rectangle(-1, W + 1, -1, H + 1, -2.5, _emitter(X_E, X_OPACITY))


def _x_scene() -> bp.Scene:
    return bp.Scene([_x_quad()], [], bp.Camera.orthographic(0, W, 0, H, 0.1, 10.0), ambient=(0, 0, 0))


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize("method", ["zbuffer", "a_buffer", "depth_peeling"])
def test_deep_holdout_samples_flatten_to_the_flat_frame_plus_their_coverage(method: str, engine: str) -> None:
    result = bp.render(_scene(), W, H, engine=engine, transparency=method, shadows="none", deep=True)
    held = _inside_fraction(HOLD, 1)
    flat = flatten(result.deep)
    # the flat frame: alpha 0 (and colour 0) where held out, the emitter elsewhere
    np.testing.assert_allclose(result.rgba[..., 3], 1.0 - held, rtol=0, atol=1e-6)
    # flattened deep frame: the same colour; alpha = the flat alpha + the holdout's coverage
    np.testing.assert_allclose(flat[..., :3], result.rgba[..., :3], rtol=0, atol=1e-6)
    np.testing.assert_allclose(flat[..., 3], result.rgba[..., 3] + held, rtol=0, atol=1e-6)
    # the holdout's samples alone: zero colour, alpha its coverage
    np.testing.assert_allclose(
        flatten(result.deep_holdout), held[..., None] * [0, 0, 0, 1], rtol=0, atol=1e-6
    )


def test_supersampled_deep_holdout_is_its_coverage() -> None:
    k = 4
    result = bp.render(_scene(), W, H, samples=k * k, transparency="a_buffer", shadows="none", deep=True)
    held = _inside_fraction(HOLD, k)
    assert 0 < held[H - 2, 2] < 1  # a corner pixel: partly held out
    np.testing.assert_allclose(
        flatten(result.deep_holdout), held[..., None] * [0, 0, 0, 1], rtol=0, atol=1e-6
    )
    # where the holdout covers a pixel wholly or not at all, flattening is exact as at one sample
    whole = (held == 0) | (held == 1)
    flat = flatten(result.deep)
    np.testing.assert_allclose(flat[whole][:, :3], result.rgba[whole][:, :3], rtol=0, atol=1e-6)
    np.testing.assert_allclose(flat[whole][:, 3], result.rgba[whole][:, 3] + held[whole], rtol=0, atol=1e-6)


def test_scene_without_holdout_has_no_holdout_image() -> None:
    result = bp.render(_x_scene(), W, H, transparency="a_buffer", shadows="none", deep=True)
    assert result.deep_holdout is None


@pytest.mark.parametrize("method", ["zbuffer", "a_buffer"])
def test_deep_merge_with_an_image_behind_the_holdout_is_cut_there(method: str) -> None:
    ours = bp.render(_scene(), W, H, transparency=method, shadows="none", deep=True)
    other = bp.render(_x_scene(), W, H, transparency="a_buffer", shadows="none", deep=True)
    held = _inside_fraction(HOLD, 1)[..., None]
    e = np.array([*_scene().meshes[0].material.emission, 1.0])
    x = other.rgba.astype(np.float64)
    np.testing.assert_allclose(x[..., 3], X_OPACITY, rtol=0, atol=1e-6)  # X covers the frame
    x_over_e = x + (1.0 - x[..., 3:]) * e
    expected = held * [0.0, 0.0, 0.0, 1.0] + (1.0 - held) * x_over_e
    merged = flatten(merge(ours.deep, other.deep))
    np.testing.assert_allclose(merged, expected, rtol=0, atol=1e-6)
    # what X contributes to the merge: X out holdout (X is in front of E, behind the holdout)
    x_part = flatten(holdout(other.deep, ours.deep))
    np.testing.assert_allclose(x_part, (1.0 - held) * x, rtol=0, atol=1e-6)
    # one render of both scenes is the merge without the holdout's own alpha: transparent (alpha 0)
    # where held out, as in Cycles
    together = bp.render(_scene(_x_quad()), W, H, transparency="a_buffer", shadows="none")
    np.testing.assert_allclose(together.rgba, (1.0 - held) * x_over_e, rtol=0, atol=1e-6)
    np.testing.assert_allclose(together.rgba, merged - held * [0.0, 0.0, 0.0, 1.0], rtol=0, atol=1e-6)
