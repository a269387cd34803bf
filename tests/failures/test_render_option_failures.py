"""Render options fed values a user really passes: numpy scalars, huge layer counts, typos, NaN points.

Each test feeds the input. The expected results come from identities: depth peeling with at
least as many layers as any sample holds equals the exact A-buffer; a numpy scalar plans like
the Python number of the same value.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from addon.options import RenderOptions
from blinn_phong.model.primitives import grid_plane, uv_sphere
from blinn_phong.shadows.volume import shadow_volume_visibility


def _scene() -> bp.Scene:
    p, t, n = uv_sphere(16, 8)
    fp, ft, fn = grid_plane(1, 1, size=(6.0, 6.0))
    floor = np.array([[1, 0, 0, 0], [0, 0, 1, -1], [0, -1, 0, 0], [0, 0, 0, 1]], float)
    glass = bp.Material(diffuse=(0.2, 0.5, 0.9), opacity=0.35)
    shift = np.array([[1, 0, 0, 0.4], [0, 1, 0, 0], [0, 0, 1, 0.9], [0, 0, 0, 1]], float)
    meshes = [
        bp.Mesh(p * 0.7, t, n),
        bp.Mesh(p * 0.5, t, n, transform=shift, material=glass),
        bp.Mesh(fp, ft, fn, transform=floor),
    ]
    cam = bp.Camera.perspective(45, 4 / 3, 0.5, 30, view=bp.look_at((0, 1, 5), (0, 0, 0)))
    return bp.Scene(meshes, [bp.DirectionalLight((-1, -2, -1))], cam)


@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_depth_peeling_with_layers_beyond_any_count_equals_the_a_buffer(engine: str) -> None:
    scene = _scene()
    exact = bp.render(scene, 64, 48, samples=4, transparency="a_buffer", engine=engine, progress=False)
    peeled = bp.render(scene, 64, 48, samples=4, transparency="depth_peeling", layers=10**30, engine=engine,
                       progress=False)  # fmt: skip
    assert peeled.plan.transparency.params["layers"] == 2**31 - 1
    assert "layers asked" in peeled.plan.transparency.reason
    np.testing.assert_allclose(peeled.rgba, exact.rgba, rtol=0, atol=1e-6)


@pytest.mark.parametrize("value", [np.float32(2.0), np.float64(2.0), np.int64(2), np.int32(2)])
def test_numpy_scalars_are_numbers(value: object) -> None:
    scene = _scene()
    a = bp.render(scene, 32, 24, tolerance=value, progress=False)
    b = bp.render(scene, 32, 24, tolerance=2.0, progress=False)
    assert a.plan.reasons() == b.plan.reasons()
    np.testing.assert_array_equal(a.rgba, b.rgba)
    assert bp.plan(scene, value).tolerance == 2.0


@pytest.mark.parametrize("bad", [-1.0, float("nan"), np.float32("inf")])
def test_bad_tolerance_names_the_argument(bad: object) -> None:
    with pytest.raises(ValueError, match=r"^tolerance: expected a finite number of 8-bit steps >= 0, got"):
        bp.render(_scene(), 8, 8, tolerance=bad, progress=False)


def test_non_number_tolerance_is_a_type_error() -> None:
    with pytest.raises(TypeError, match="tolerance: expected a number"):
        bp.render(_scene(), 8, 8, tolerance="2", progress=False)


def test_render_options_store_their_declared_types() -> None:
    """RenderOptions validates once and stores ints as ints: render() accepts what it holds."""
    from addon.pipeline import render_frame

    options = RenderOptions(peel_layers=4.0, transparency="DEPTH_PEELING", samples_per_axis=np.int64(2))
    assert type(options.peel_layers) is int and options.peel_layers == 4
    assert type(options.samples_per_axis) is int
    result = render_frame(_scene(), 32, 24, options)
    assert result is not None
    with pytest.raises(ValueError, match="peel_layers: expected an integer"):
        RenderOptions(peel_layers=4.5)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: bp.render(_scene(), 8, 8, shadows="shadow_mpa"), "did you mean 'shadow_map'"),
        (lambda: bp.render(_scene(), 8, 8, transparency="abuffer"), "did you mean 'a_buffer'"),
        (lambda: bp.render(_scene(), 8, 8, shading="phonng"), "did you mean 'phong'"),
        (lambda: bp.ShadowOptions(method="raytraced"), "did you mean 'ray_traced'"),
        (lambda: bp.ShadowOptions(kernel="bilinaer"), "did you mean 'bilinear'"),
        (lambda: bp.Fog(mode="expo"), "did you mean 'exp'"),
        (lambda: bp.Material(opacity=0.5, transparency_model="absorbtion"), "did you mean 'absorption'"),
        (lambda: RenderOptions(transparency="ABUFFER"), "did you mean 'A_BUFFER'"),
        (
            lambda: bp.Texture(np.ones((2, 2, 4), np.float32), extension="clamp_to_edge"),
            "did you mean 'extend'",
        ),
        (lambda: bp.Texture(np.ones((2, 2, 4), np.float32), extension="repaet"), "did you mean 'repeat'"),
        (
            lambda: bp.Texture(np.ones((2, 2, 4), np.float32), interpolation="nearest"),
            "did you mean 'closest'",
        ),
        (lambda: RenderOptions(shadows="hard"), "did you mean 'HARD'"),
        (
            lambda: shadow_volume_visibility(
                bp.PointLight((0, 1, 0)),
                np.zeros((1, 3, 3)),
                np.zeros((1, 3)),
                np.ones((1, 3)),
                stencil="z-fail",
            ),
            "did you mean 'zfail'",
        ),
    ],
)
def test_misspelled_names_get_a_suggestion(call, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        call()


def test_unrelated_names_get_no_suggestion() -> None:
    with pytest.raises(ValueError) as info:
        bp.render(_scene(), 8, 8, shadows="banana")
    assert "did you mean" not in str(info.value)
    assert "'shadow_map'" in str(info.value)  # the valid names are still listed


@pytest.mark.parametrize(
    ("points", "normals", "name"),
    [
        (np.array([[np.nan, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]), "points"),
        (np.array([[0.0, 0.0, 0.0]]), np.array([[np.inf, 1.0, 0.0]]), "normals"),
    ],
)
def test_shadow_volume_visibility_names_the_bad_array(points, normals, name: str) -> None:
    tris = np.array([[[-1.0, 1.0, -1.0], [1.0, 1.0, -1.0], [0.0, 1.0, 1.0]]])
    with pytest.raises(ValueError, match=rf"^{name}: "):
        shadow_volume_visibility(bp.PointLight((0.0, 3.0, 0.0)), tris, points, normals)


def test_cost_model_helpers_accept_numpy_scalars() -> None:
    """The calibrated choosers take the numpy numbers a caller computes them from."""
    from blinn_phong.planning import calibration as cal

    models = cal.shipped_models()
    expected = cal.choose_depth_peeling(models, 4.0, 0.5, 1.0, 4)
    for tolerance in (np.float32(4.0), np.int64(4)):
        assert cal.choose_depth_peeling(models, tolerance, np.float32(0.5), np.float64(1.0), 4) == expected
