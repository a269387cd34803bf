"""Transparent casters cast coloured shadows through their transmittance (closed forms).

Ground points under thin filters lit from straight above: the light reaching a point is
the product of the transmittances of the filters above it (each filter multiplies what
passes by its per-channel transmittance; an opaque triangle has transmittance 0), and 1
where nothing is above. Points are drawn away from the filters' edges (by far more than
the ray offset), so each is under a known set of filters.
"""

import numpy as np
import pytest

from blinn_phong.model.lights import DirectionalLight, PointLight
from blinn_phong.shadows.methods import light_visibility
from blinn_phong.shadows.raytrace import RayScene, transmitted_light

from .geometry import box_triangles, quad_triangles

GROUND = quad_triangles(np.array([-4.0, -4.0, 0.0]), np.array([8.0, 0, 0]), np.array([0, 8.0, 0]))
RED_PANE = quad_triangles(
    np.array([-2.0, -1.0, 1.0]), np.array([2.0, 0, 0]), np.array([0, 2.0, 0])
)  # x ∈ [-2, 0]
BLUE_PANE = quad_triangles(
    np.array([-1.0, -1.0, 1.5]), np.array([2.0, 0, 0]), np.array([0, 2.0, 0])
)  # x ∈ [-1, 1]
BOX = box_triangles((1.5, -0.5, 0.5), (2.5, 0.5, 1.0))  # opaque, x ∈ [1.5, 2.5]
RED_T = (0.9, 0.3, 0.2)
BLUE_T = (0.2, 0.4, 0.8)


def scene_and_transmittance():
    tris = np.concatenate([GROUND, RED_PANE, BLUE_PANE, BOX])
    t = np.concatenate(
        [
            np.zeros((len(GROUND), 3)),  # the ground is opaque (it never lies between a point and the light)
            np.tile(RED_T, (len(RED_PANE), 1)),
            np.tile(BLUE_T, (len(BLUE_PANE), 1)),
            np.zeros((len(BOX), 3)),
        ]
    )
    return tris, t


def expected(x: np.ndarray) -> np.ndarray:
    """Closed form along y = 0 for light from straight above."""
    out = np.ones((len(x), 3))
    out[(x > -2) & (x < 0)] *= RED_T
    out[(x > -1) & (x < 1)] *= BLUE_T
    out[(x > 1.5) & (x < 2.5)] = 0.0
    return out


def ground_line(n=400):
    x = np.linspace(-3.5, 3.5, n)
    edges = np.array([-2.0, -1.0, 0.0, 1.0, 1.5, 2.5])
    x = x[np.min(np.abs(x[:, None] - edges[None, :]), axis=1) > 0.05]  # away from every edge
    y = np.random.default_rng(5).uniform(-0.4, 0.4, len(x))
    return x, np.column_stack([x, y, np.zeros(len(x))]), np.tile([0.0, 0.0, 1.0], (len(x), 1))


def test_stacked_filters_multiply_and_opaque_casters_block():
    tris, t = scene_and_transmittance()
    x, p, n = ground_line()
    got = transmitted_light(RayScene(tris), p, n, (0.0, 0.0, 1.0), t)
    np.testing.assert_allclose(got, expected(x), rtol=0, atol=1e-12)
    assert {tuple(np.round(v, 6)) for v in got} >= {RED_T, BLUE_T, (0.18, 0.12, 0.16), (1, 1, 1), (0, 0, 0)}


def test_light_visibility_gives_coloured_shadows_behind_a_parameter():
    tris, t = scene_and_transmittance()
    x, p, n = ground_line()
    sun = DirectionalLight((0.0, 0.0, -1.0))
    coloured = light_visibility("ray_traced", sun, tris, p, n, transmittance=t)
    np.testing.assert_allclose(coloured, expected(x), rtol=0, atol=1e-12)
    full = light_visibility("ray_traced", sun, tris, p, n)  # without it: every caster casts full shadow
    np.testing.assert_array_equal(full, np.where(np.all(expected(x) == 1, axis=1), 1.0, 0.0))
    # a point light high above: same filters, same products (no edge lies near the points' rays)
    lamp = PointLight((0.0, 0.0, 1e4))
    far = light_visibility("ray_traced", lamp, tris, p, n, transmittance=t)
    np.testing.assert_allclose(far, expected(x), rtol=0, atol=1e-12)
    assert light_visibility("none", sun, tris, p, n, transmittance=t).shape == (len(p), 3)
    with pytest.raises(ValueError, match="transmittance"):
        light_visibility("shadow_map", sun, tris, p, n, transmittance=t)
    with pytest.raises(ValueError, match="transmittance"):
        transmitted_light(RayScene(tris), p, n, (0.0, 0.0, 1.0), t[:-1])
    with pytest.raises(ValueError, match="transmittance"):
        transmitted_light(RayScene(tris), p, n, (0.0, 0.0, 1.0), t * 2)


def test_more_filters_than_allowed_count_as_blocked():
    tris, t = scene_and_transmittance()
    x, p, n = ground_line()
    got = transmitted_light(RayScene(tris), p, n, (0.0, 0.0, 1.0), t, max_layers=1)
    two = (x > -1) & (x < 0)  # under both panes: the second filter is beyond the limit
    assert np.all(got[two] == 0)
    np.testing.assert_allclose(got[~two], expected(x)[~two], rtol=0, atol=1e-12)
