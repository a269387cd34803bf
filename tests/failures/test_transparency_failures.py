"""Where transparency methods fail: sorting interpenetrating surfaces, weighted blended OIT at high opacity.

The exact result at a pixel is the ``over`` of its surfaces in depth order (Porter & Duff
1984), written out here in closed form; the failing method's error must exceed a bound
derived from that formula, the robust method (the A-buffer) must match it, and no output
may hold NaN or Inf.
"""

from __future__ import annotations

import numpy as np

import blinn_phong as bp
from blinn_phong.effects.oit import (
    resolve_a_buffer,
    resolve_transparency,
    resolve_weighted_blended,
    wboit_weights,
)
from blinn_phong.geometry.raster import rasterize
from testbeds.error_metrics import error_metrics, has_nonfinite

SIZE = 48
RED, BLUE = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])


def _quad(corners: np.ndarray, colour: np.ndarray, opacity: float) -> bp.Mesh:
    n = np.cross(corners[1] - corners[0], corners[2] - corners[0])
    n = n / np.linalg.norm(n)
    # Emission only, no lights: the surface's straight colour is exactly ``colour``.
    mat = bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=tuple(colour), opacity=opacity)
    return bp.Mesh(corners, np.array([[0, 1, 2], [0, 2, 3]]), np.tile(n, (4, 1)), material=mat)


def _crossing_quads(opacity: float) -> tuple[bp.Scene, float]:
    """Two quads seen from above that cross along x = 0: red is z = 0.5·x, blue is z = −0.5·x."""
    xs = np.array([-1.0, 1.0, 1.0, -1.0])
    ys = np.array([-1.0, -1.0, 1.0, 1.0])
    red = _quad(np.stack([xs, ys, 0.5 * xs], 1), RED, opacity)
    blue = _quad(np.stack([xs, ys, -0.5 * xs], 1), BLUE, opacity)
    camera = bp.Camera.orthographic(-1, 1, -1, 1, 0.1, 20.0, view=bp.look_at((0, 0, 10), (0, 0, 0)))
    return bp.Scene([red, blue], [], camera, ambient=(0, 0, 0)), opacity


def _exact_crossing(opacity: float, background: np.ndarray) -> np.ndarray:
    """Closed form: at pixel centre x the nearer quad (larger z, the camera looks down −z) is in front."""
    x = (np.arange(SIZE) + 0.5) / SIZE * 2 - 1
    x = np.broadcast_to(x, (SIZE, SIZE)).reshape(-1)
    a = opacity
    front = np.where((x > 0)[:, None], RED, BLUE)  # red z = x/2 > blue z = −x/2 where x > 0
    back = np.where((x > 0)[:, None], BLUE, RED)
    rgb = a * front + (1 - a) * (a * back + (1 - a) * background[:, :3])
    return np.c_[rgb, np.ones(len(rgb))]


def _fragments(scene: bp.Scene) -> dict:
    prepared = bp.prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, SIZE, SIZE)
    shaded = bp.shade_fragments(prepared, frags, shading="flat")
    return {
        "pixel": frags.pixel,
        "depth": frags.depth,
        "rgba": np.c_[shaded.rgb * shaded.alpha[:, None], shaded.alpha],
        "triangle": frags.triangle,
        "triangle_mesh": prepared.triangle_mesh,
        "triangle_eye_distance": -prepared.face_eye_centroid[:, 2],
        "front_facing": frags.front_facing,
    }


def test_back_to_front_sorting_fails_on_interpenetrating_surfaces() -> None:
    opacity = 0.5
    scene, _ = _crossing_quads(opacity)
    fr = _fragments(scene)
    background = np.tile([0.0, 0.0, 0.0, 1.0], (SIZE * SIZE, 1))
    exact = _exact_crossing(opacity, background)
    args = (fr["pixel"], fr["depth"], fr["rgba"], SIZE * SIZE)
    common = {k: fr[k] for k in ("triangle", "triangle_mesh", "triangle_eye_distance", "front_facing")}
    sorted_objects = resolve_transparency("sort_objects", *args, background=background, **common)
    a_buffer = resolve_a_buffer(*args, background)
    assert not has_nonfinite(sorted_objects, a_buffer)
    assert error_metrics(a_buffer, exact)["max_steps"] < 1e-6
    # Closed form: swapping the order of two layers A, B of opacity a changes
    # A + (1−a)B into B + (1−a)A: a difference of a·(A − B) = a²(front − back) per channel,
    # 0.25 here = 63.75 steps, on the half of the image where the object order is wrong.
    err = error_metrics(sorted_objects, exact)
    assert err["max_steps"] > 63.0
    wrong = np.abs(sorted_objects - exact).max(axis=1) > 0.2
    assert 0.4 < wrong.mean() < 0.6


def test_weighted_blended_oit_fails_at_high_opacity() -> None:
    # Two layers per pixel, red in front (window depth 0.50) and blue behind (0.52), over black.
    n = 64
    pixel = np.repeat(np.arange(n), 2)
    depth = np.tile([0.50, 0.52], n)
    errors = {}
    for opacity in (0.1, 0.95):
        rgba = np.tile(np.r_[opacity * RED, opacity, opacity * BLUE, opacity].reshape(2, 4), (n, 1))
        background = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
        a = opacity
        exact_rgb = a * RED + (1 - a) * a * BLUE
        exact = np.tile(np.r_[exact_rgb, 1.0], (n, 1))
        weights = wboit_weights(rgba[:, 3], "eq10", window_depth=depth)
        wboit = resolve_weighted_blended(pixel, weights, rgba, n, background)
        a_buffer = resolve_a_buffer(pixel, depth, rgba, n, background)
        assert not has_nonfinite(wboit, a_buffer)
        assert error_metrics(a_buffer, exact)["max_steps"] < 1e-6
        errors[opacity] = error_metrics(wboit, exact)["max_steps"]
        # Closed form of WBOIT (McGuire & Bavoil 2013, eq. 6): colour = Σ wᵢαᵢcᵢ / Σ wᵢαᵢ · (1 − Π(1−αᵢ)).
        # With eq. 10 weights the ratio r = w_front/w_back = ((1 − 0.50)/(1 − 0.52))³ ≈ 1.13 (both
        # above the 1e-2 floor), so red = r/(1 + r)·(1 − (1 − a)²) while the exact red is a.
        r = (0.50 / 0.48) ** 3
        predicted_red = r / (1 + r) * (1 - (1 - a) ** 2)
        assert np.allclose(wboit[:, 0], predicted_red, atol=1e-9)
    # At a = 0.95: predicted red 0.53·0.9975 = 0.53 against 0.95: 0.42 = 107 steps off.
    assert errors[0.95] > 100.0
    # At a = 0.1 the same formula gives red 0.53·0.19 = 0.10 against 0.10: within 1 step.
    assert errors[0.1] < 1.0
