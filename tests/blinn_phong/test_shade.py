"""blinn_phong.frame.lighting.shade and shade_many on both engines: input checks with counts, and the
guarded cases of the shared light terms (OpenGL 2.1 §2.14.1 by hand)."""

from __future__ import annotations

import numpy as np
import pytest

from blinn_phong._numba import numba_available
from blinn_phong.frame.lighting import lights_in_eye_space, shade, shade_many
from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.model.scene import LightModel, Material

# --------------------------------------------------------------------------- shade() input checks

ENGINES = ["numpy", pytest.param("numba", marks=pytest.mark.skipif(not numba_available(), reason="no numba"))]
MATERIAL = Material(ambient=(0.2, 0.2, 0.2), diffuse=(0.8, 0.8, 0.8), specular=(1, 1, 1), shininess=20)
LIGHTS = lights_in_eye_space([DirectionalLight(direction=(0, 0, -1))], np.eye(4))
POINTS = np.array([[0.0, 0.0, -3.0], [0.0, 0.0, -2.0]])  # on the view axis: h = l = v
UP = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])


def _shade_both(points, normals, engine):
    yield lambda: shade(points, normals, MATERIAL, LIGHTS, engine=engine)
    yield lambda: shade_many(points, normals, np.zeros(len(points), int), [MATERIAL], LIGHTS, engine=engine)


@pytest.mark.parametrize("engine", ENGINES)
def test_shade_rejects_non_finite_normals_and_points_with_a_count(engine):
    nan_normal = UP.copy()
    nan_normal[1, 0] = np.nan
    inf_point = POINTS.copy()
    inf_point[0, 2] = -np.inf
    for call in _shade_both(POINTS, nan_normal, engine):
        with pytest.raises(ValueError, match=r"^normals: expected finite values; got 1 NaN and 0 Inf of 6"):
            call()
    for call in _shade_both(inf_point, UP, engine):
        with pytest.raises(ValueError, match=r"^points: expected finite values; got 0 NaN and 1 Inf of 6"):
            call()


@pytest.mark.parametrize("engine", ENGINES)
def test_shade_rejects_normals_that_are_neither_unit_nor_zero(engine):
    for call in _shade_both(POINTS, 2.0 * UP, engine):
        with pytest.raises(
            ValueError, match=r"^normals: expected unit vectors \(length 1 ± 1e-05\).*got 2 of 2"
        ):
            call()
    for call in _shade_both(POINTS, (1 + 2e-5) * UP, engine):
        with pytest.raises(ValueError, match=r"^normals: .*row 0: length 1\.0000"):
            call()


@pytest.mark.parametrize("engine", ENGINES)
def test_shade_accepts_zero_and_nearly_unit_normals(engine):
    # OpenGL §2.14.1 with a light along the view axis: zero normal -> ambient only (0.2·0.2 global
    # + 0.2·0 light ambient); unit normal facing it -> + d·cos 0 + s·1^20 = 0.04 + 0.8 + 1
    normals = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0 + 5e-6]])
    terms = shade(POINTS, normals, MATERIAL, LIGHTS, engine=engine)
    np.testing.assert_allclose(terms.color[0], 0.04, atol=1e-12)
    np.testing.assert_allclose(terms.color[1], 0.04 + (0.8 + 1.0) * (1 + 5e-6), rtol=1e-4)


# ------------------------------------------------------------ one lighting equation, two engines


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("specular", ["blinn", "phong"])
def test_guarded_cases_of_the_shared_light_terms(engine, specular):
    # OpenGL 2.1 §2.14.1 by hand, identity view (eye space = world), local viewer, d_cm = s_cm = 1
    material = Material(ambient=(0, 0, 0), diffuse=(1, 1, 1), specular=(1, 1, 1), shininess=1)
    model = LightModel(local_viewer=True, specular=specular)
    up = (0.0, 0.0, 1.0)
    cases = [
        # point at the eye (v defaults to +z), light straight ahead: n·l = 1, h = r = (0, 0, 1)
        ([DirectionalLight(direction=(0, 0, -1))], (0, 0, 0), up, 1.0, 1.0),
        # point at a point light: l = 0, so no diffuse or specular (and no NaN)
        ([PointLight(position=(0, 0, -2))], (0, 0, -2), up, 0.0, 0.0),
        # outside a 10° spot cone (45° off its axis): nothing
        (
            [SpotLight(position=(0, 0, 0), direction=(0, 0, -1), cutoff=10, exponent=2)],
            (1, 0, -1),
            up,
            0.0,
            0.0,
        ),
        # on the spot axis at d = 3 with k_l = 0.5: att = 1/(1 + 1.5) = 0.4, spot = 1^2
        (
            [SpotLight(position=(0, 0, 0), direction=(0, 0, -1), cutoff=10, exponent=2, linear=0.5)],
            (0, 0, -3),
            up,
            0.4,
            0.4,
        ),
        # zero normal: ambient and emission only
        ([DirectionalLight(direction=(0, 0, -1))], (0, 0, -1), (0, 0, 0), 0.0, 0.0),
    ]
    for lights, point, normal, diffuse, highlight in cases:
        terms = shade(
            np.array([point], float),
            np.array([normal], float),
            material,
            lights_in_eye_space(lights, np.eye(4)),
            global_ambient=(0, 0, 0),
            model=model,
            engine=engine,
        )
        np.testing.assert_allclose(terms.diffuse[0], diffuse, atol=1e-15)
        np.testing.assert_allclose(terms.specular[0], highlight, atol=1e-15)
