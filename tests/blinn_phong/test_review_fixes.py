"""Regression tests for review findings on the core packages, each against a closed form."""

from __future__ import annotations

import numpy as np
import pytest

from blinn_phong.fast import numba_available
from blinn_phong.fog import apply_fog, fog_factor
from blinn_phong.lighting import lights_in_eye_space, shade, shade_many
from blinn_phong.normals import normalize
from blinn_phong.oit import resolve_weighted_blended, transparency_pass, wboit_weights
from blinn_phong.raster import Fragments
from blinn_phong.scene import DirectionalLight, LightModel, Material, PointLight, SpotLight
from blinn_phong.transparency import (
    TRANSPARENCY_MODELS,
    blend_transparent_surface,
    transparent_fragment,
)

# ------------------------------------------------------------- one meaning per transparency model

OPAQUE_BEHIND = np.array([[0.2, 0.4, 0.6, 1.0], [0.05, 0.5, 0.25, 1.0]])
TRANSLUCENT_BEHIND = np.array([[0.1, 0.0, 0.3, 0.5], [0.0, 0.0, 0.0, 0.0]])
LIT = np.array([[0.7, 0.2, 0.1], [1.5, 0.3, 0.0]])  # may exceed 1 (unclamped light)
ALPHA = np.array([0.25, 0.6])


def test_emission_is_scaled_by_opacity():
    # Material docstring: emission adds α·c and hides nothing.
    for behind in (OPAQUE_BEHIND, TRANSLUCENT_BEHIND):
        out = blend_transparent_surface(LIT, behind, "emission", opacity=ALPHA)
        np.testing.assert_allclose(out[:, :3], ALPHA[:, None] * LIT + behind[:, :3], atol=1e-15)
        np.testing.assert_array_equal(out[:, 3], behind[:, 3])


def test_absorption_takes_the_grey_filter_of_an_opacity():
    # a material of opacity α filters with T = 1 − α and adds its own light: c + (1 − α)·behind
    out = blend_transparent_surface(LIT[0], OPAQUE_BEHIND, "absorption", transmittance=0.75)
    np.testing.assert_allclose(out[:, :3], LIT[0] + 0.75 * OPAQUE_BEHIND[:, :3], atol=1e-15)
    np.testing.assert_array_equal(out[:, 3], OPAQUE_BEHIND[:, 3])


@pytest.mark.parametrize(
    ("model", "kwargs", "name"),
    [
        ("absorption", {"opacity": 0.5, "transmittance": 0.5}, "opacity"),
        ("emission", {"transmittance": 0.5}, "transmittance"),
        ("partial_occlusion", {"opacity": 0.5, "transmittance": np.ones(3)}, "transmittance"),
    ],
)
def test_a_parameter_the_model_does_not_use_is_refused(model, kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name}: the .* does not use it"):
        blend_transparent_surface(LIT, OPAQUE_BEHIND, model, **kwargs)


@pytest.mark.parametrize("model", TRANSPARENCY_MODELS)
def test_fragment_over_an_opaque_background_is_the_model(model):
    # the renderer resolves fragments with src over: (α·c, α), (α·c, 0), (c, α) must give the models
    frag = transparent_fragment(LIT, ALPHA, model)
    over = frag[:, :3] + (1 - frag[:, 3:]) * OPAQUE_BEHIND[:, :3]  # Porter–Duff over, premultiplied
    if model == "absorption":
        expected = blend_transparent_surface(
            LIT, OPAQUE_BEHIND, model, transmittance=np.repeat(1 - ALPHA[:, None], 3, axis=1)
        )
    else:
        expected = blend_transparent_surface(LIT, OPAQUE_BEHIND, model, opacity=ALPHA)
    np.testing.assert_allclose(over, expected[:, :3], atol=1e-15)
    np.testing.assert_allclose(
        frag[:, 3] + (1 - frag[:, 3]) * OPAQUE_BEHIND[:, 3], expected[:, 3], atol=1e-15
    )


def test_transparency_inputs_are_checked_in_the_shared_style():
    bad = np.array([[np.nan, 0.0, 0.0], [0.0, np.inf, 0.0]])
    with pytest.raises(ValueError, match=r"^surface_rgb: expected finite values; got 1 NaN and 1 Inf of 6"):
        blend_transparent_surface(bad, OPAQUE_BEHIND, "emission")
    with pytest.raises(ValueError, match=r"^opacity: expected values in \[0, 1\]; got 1 of 2 outside"):
        blend_transparent_surface(LIT, OPAQUE_BEHIND, "partial_occlusion", opacity=np.array([0.5, 1.5]))
    with pytest.raises(TypeError, match=r"^behind: expected real numbers, got dtype <U1"):
        blend_transparent_surface(LIT, np.array(["a", "b", "c", "d"]), "emission")


def test_fragments_of_emission_and_partial_occlusion_match_over_any_background():
    for model in ("emission", "partial_occlusion"):
        frag = transparent_fragment(LIT, ALPHA, model)
        over = frag + (1 - frag[:, 3:]) * TRANSLUCENT_BEHIND
        np.testing.assert_allclose(
            over, blend_transparent_surface(LIT, TRANSLUCENT_BEHIND, model, opacity=ALPHA), atol=1e-15
        )


# --------------------------------------------------------------------------- normalize


def test_normalize_integer_vectors_gives_float64():
    out = normalize(np.array([[3, 4, 0], [0, 0, -2]]))
    assert out.dtype == np.float64
    np.testing.assert_allclose(out, [[0.6, 0.8, 0.0], [0.0, 0.0, -1.0]], atol=1e-16)


@pytest.mark.parametrize(
    ("vector", "dtype", "expected"),
    [
        ([1e-200, 0, 0], np.float64, [1, 0, 0]),  # |v|² underflows to 0
        ([1e200, 1e200, 0], np.float64, [2**-0.5, 2**-0.5, 0]),  # |v|² overflows to inf
        ([0, -3e-160, 4e-160], np.float64, [0, -0.6, 0.8]),
        ([1e-23, 0, 0], np.float32, [1, 0, 0]),
        ([3e19, 0, 0], np.float32, [1, 0, 0]),
        ([0, 3e20, -4e20], np.float32, [0, 0.6, -0.8]),
    ],
)
def test_normalize_lengths_whose_square_under_or_overflows(vector, dtype, expected):
    out = normalize(np.array(vector, dtype=dtype))
    assert out.dtype == dtype
    np.testing.assert_allclose(out, expected, rtol=4 * np.finfo(dtype).eps, atol=0)


def test_normalize_keeps_zero_vectors_zero():
    np.testing.assert_array_equal(normalize(np.zeros((2, 3), np.float32)), np.zeros((2, 3), np.float32))


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


# --------------------------------------------------------------------------- fog parameters


@pytest.mark.parametrize(
    ("start", "end", "name"),
    [(0.0, np.inf, "end"), (np.nan, 10.0, "start"), (-np.inf, 10.0, "start"), (2.0, np.nan, "end")],
)
def test_linear_fog_needs_finite_start_and_end(start, end, name):
    with pytest.raises(ValueError, match=rf"^{name}: expected a finite number"):
        fog_factor(np.array([1.0, 5.0]), "linear", start=start, end=end)


def test_linear_fog_end_before_start_is_reverse_fog():
    # GL §3.10 f = (end − c)/(end − start) does not require end > start: here f = (c − 2)/8, clamped
    np.testing.assert_allclose(
        fog_factor(np.array([2.0, 6.0, 12.0]), "linear", start=10.0, end=2.0), [0.0, 0.5, 1.0], atol=1e-15
    )


def test_fog_reports_non_finite_counts_in_the_shared_style():
    with pytest.raises(ValueError, match=r"^distance: expected finite values; got 1 NaN and 2 Inf of 4"):
        fog_factor(np.array([np.nan, np.inf, -np.inf, 1.0]))
    with pytest.raises(ValueError, match=r"^rgba: expected shape \(\.\.\., 4\), got shape \(2, 3\)"):
        apply_fog(np.zeros((2, 3)), np.zeros(2), (0, 0, 0))


# ---------------------------------------------------------- transparency_pass opaque z-buffer


def _fragments(pixel, depth, triangle, width=3):
    n = len(pixel)
    return Fragments(
        width,
        1,
        1,
        np.asarray(pixel, np.int64),
        np.zeros(n, np.int64),
        np.asarray(depth, np.float64),
        np.asarray(triangle, np.int64),
        np.full((n, 3), 1 / 3),
        np.ones(n, bool),
    )


# pixel 0: opaque at 0.5 (tri 1) and 0.3 (tri 2) -> the nearer, tri 2;
# pixel 1: two opaque at the same depth 0.4 (tri 3 and tri 0) -> GL_LESS keeps the first drawn, tri 0;
#          a transparent fragment (tri 4) in front at 0.2; pixel 2: empty
FRAGS = _fragments([0, 0, 1, 1, 1], [0.5, 0.3, 0.4, 0.4, 0.2], [1, 2, 3, 0, 4])
OPAQUE = np.array([True, True, True, True, False])
COLOURS = np.array([[0.1, 0, 0, 1], [0.2, 0, 0, 1], [0.3, 0, 0, 1], [0.4, 0, 0, 1], [0, 0, 0.25, 0.5]])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("method", ["zbuffer", "a_buffer"])
def test_transparency_pass_keeps_the_shade_dtype_and_resolves_like_gl_less(dtype, method):
    shaded = []

    def shade(index):
        shaded.append(np.sort(index))
        return COLOURS[index].astype(dtype)

    rgba, depth = transparency_pass(
        FRAGS, OPAQUE, shade, method, triangle_mesh=np.zeros(5, int), triangle_eye_distance=np.zeros(5)
    )
    assert rgba.dtype == dtype
    np.testing.assert_array_equal(depth, [0.3, 0.4, 1.0])
    np.testing.assert_array_equal(shaded[0], [1, 3])  # only the visible opaque fragments are shaded
    expected_pixel1 = COLOURS[3] if method == "zbuffer" else COLOURS[4] + 0.5 * COLOURS[3]  # over
    np.testing.assert_allclose(rgba, np.array([COLOURS[1], expected_pixel1, np.zeros(4)]), atol=1e-7)


# --------------------------------------------------------------------------- WBOIT floor on one layer


def test_wboit_one_layer_is_exact_above_the_floor_and_scaled_below_it():
    # McGuire & Bavoil 2013, eq. 10 weight α·max(1e-2, 3e3·(1 − d)³) and the listing's max(accum.a, 1e-5)
    alpha = np.array([0.01, 0.01, 0.5, 0.05, 0.9])
    depth = np.array([0.99, 0.5, 0.99, 0.9, 0.999])
    colour = 0.8
    w = wboit_weights(alpha, "eq10", window_depth=depth)
    np.testing.assert_allclose(w, alpha * np.maximum(1e-2, 3e3 * (1 - depth) ** 3), rtol=1e-15)
    rgba = np.c_[np.full((5, 3), colour) * alpha[:, None], alpha]
    out = resolve_weighted_blended(np.arange(5), w, rgba, 5)
    accum_a = w * alpha
    np.testing.assert_allclose(out[:, 3], alpha, rtol=1e-15)  # coverage always exact
    expected = colour * alpha * np.minimum(1.0, accum_a / 1e-5)
    np.testing.assert_allclose(out[:, 0], expected, rtol=1e-12)
    # the reviewer's case: α = 0.01 at depth 0.99 resolves to 0.0008 instead of 0.008
    np.testing.assert_allclose(out[0, 0], 0.0008, rtol=1e-12)
    above = accum_a >= 1e-5
    assert above.any() and (~above).any()
    np.testing.assert_allclose(out[above, 0], colour * alpha[above], rtol=1e-12)


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
