"""Deep output of the renderer (``render(..., deep=True)``, :func:`blinn_phong.frame.deep_output.render_deep`)
against its flat renders.

Oracle: :func:`blinn_phong.frame.render` with the A-buffer (or depth peeling) on the same scene:
flattening the deep frame must give the flat frame, for every transparency model, fog and
Kay–Greenberg opacity, in bands and strips and with the compiled stages, and two renders of
separate object sets that interpenetrate, deep-merged, must give one render of both. The deep
image comes from the same pass as the flat frame: the frame is rasterized once.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.frame import pipeline, visibility
from blinn_phong.frame.deep_output import render_deep
from blinn_phong.model.primitives import grid_plane, uv_sphere
from compositing.deep import flatten, merge

W, H = 48, 36
CAMERA = bp.Camera.perspective(50, 4 / 3, 1.0, 12, view=bp.look_at((0.5, -4.0, 2.0), (0, 0, 0), (0, 0, 1)))
LIGHTS = [bp.DirectionalLight((0.3, 0.4, -1)), bp.PointLight((1.5, -1, 2.5), quadratic=0.1)]

MATERIALS = {
    "partial_occlusion": bp.Material(
        diffuse=(0.2, 0.4, 0.9), specular=(0.9, 0.9, 0.9), shininess=40, opacity=0.5
    ),
    "emission": bp.Material(diffuse=(0.9, 0.3, 0.2), opacity=0.4, transparency_model="emission"),
    "absorption": bp.Material(diffuse=(0.3, 0.9, 0.3), opacity=0.6, transparency_model="absorption"),
    "kay_greenberg": bp.Material(diffuse=(0.8, 0.8, 0.2), opacity=0.5, kay_greenberg=(0.1, 0.8, 2.5)),
    "washout": bp.Material(
        diffuse=(0.5, 0.5, 0.5), specular=(1, 1, 1), shininess=20, opacity=0.3, specular_washout=True
    ),
}


def spheres(materials: list, seed: int = 5) -> list[bp.Mesh]:
    pos, tris, normals = uv_sphere(20, 10)
    rng = np.random.default_rng(seed)
    meshes = []
    for material in materials:
        t = np.eye(4)
        t[:3, :3] *= rng.uniform(0.5, 0.9)
        t[:3, 3] = rng.uniform(-0.8, 0.8, 3)
        meshes.append(bp.Mesh(pos, tris, normals, transform=t, material=material))
    return meshes


def floor_and_ball() -> list[bp.Mesh]:
    plane, ptris, pnormals = grid_plane(2, 2, (6, 6))
    floor = np.eye(4)
    floor[2, 3] = -1.2
    pos, tris, normals = uv_sphere(20, 10)
    t = np.eye(4)
    t[:3, :3] *= 0.4
    return [bp.Mesh(plane, ptris, pnormals, transform=floor), bp.Mesh(pos, tris, normals, transform=t)]


def scene(meshes: list[bp.Mesh]) -> bp.Scene:
    return bp.Scene(meshes, LIGHTS, CAMERA, light_model=bp.LightModel(two_sided=True))


@pytest.mark.parametrize("model", [*MATERIALS, "all"])
def test_flattened_deep_frame_is_the_a_buffer_frame(model):
    materials = list(MATERIALS.values()) if model == "all" else [MATERIALS[model]] * 3
    s = scene(spheres(materials) + floor_and_ball())
    flat = bp.render(s, W, H, transparency="a_buffer", shadows="none", engine="numpy")
    deep = render_deep(s, W, H, transparency="a_buffer", shadows="none", engine="numpy")
    assert deep.counts.max() >= 3  # transparent layers over an opaque one
    np.testing.assert_allclose(flatten(deep), flat.rgba, rtol=0, atol=1e-6)


@pytest.mark.parametrize(
    "options",
    [
        {"transparency": "depth_peeling", "layers": 2},
        {"transparency": "zbuffer"},
        {"transparency": "a_buffer", "fog": bp.Fog("exp", (0.5, 0.6, 0.7), density=0.3)},
    ],
    ids=["peeling2", "zbuffer", "fog"],
)
def test_flattened_deep_frame_follows_the_method(options):
    s = scene(spheres(list(MATERIALS.values())) + floor_and_ball())
    flat = bp.render(s, W, H, shadows="none", engine="numpy", **options)
    deep = render_deep(s, W, H, shadows="none", engine="numpy", **options)
    np.testing.assert_allclose(flatten(deep), flat.rgba, rtol=0, atol=1e-6)


def test_separate_renders_that_interpenetrate_merge_into_one():
    materials = list(MATERIALS.values())
    meshes = spheres(materials) + floor_and_ball()
    first, second = meshes[0::2], meshes[1::2]  # interpenetrating spheres split between the two sets
    both = bp.render(scene(meshes), W, H, transparency="a_buffer", shadows="none", engine="numpy")
    a = render_deep(scene(first), W, H, shadows="none", engine="numpy")
    b = render_deep(scene(second), W, H, shadows="none", engine="numpy")
    np.testing.assert_allclose(flatten(merge(a, b)), both.rgba, rtol=0, atol=1e-6)
    flat_a = bp.render(scene(first), W, H, transparency="a_buffer", shadows="none", engine="numpy").rgba
    flat_b = bp.render(scene(second), W, H, transparency="a_buffer", shadows="none", engine="numpy").rgba
    over = flat_a + (1 - flat_a[..., 3:]) * flat_b
    assert np.abs(over - both.rgba).max() > 0.05  # flat compositing cannot


def test_supersampled_deep_frame_is_exact_where_coverage_is_whole():
    s = scene(spheres(list(MATERIALS.values())) + floor_and_ball())
    flat = bp.render(
        s, W, H, samples=4, transparency="a_buffer", shadows="none", engine="numpy", shading="flat"
    )
    deep = flatten(render_deep(s, W, H, samples=4, shadows="none", engine="numpy", shading="flat"))
    error = np.abs(deep - flat.rgba).max(axis=-1)
    # Pixels inside one triangle of every surface they show (flat shading: one colour per
    # triangle) are exact; edges and crossings follow the coverage bound of docs/compositing.md.
    one_sample = render_deep(s, W, H, samples=1, shadows="none", engine="numpy", shading="flat")
    assert (error <= 1e-6).mean() > 0.5
    assert error.max() < 0.5 and one_sample.n_samples > 0


def test_methods_without_a_depth_order_are_refused():
    with pytest.raises(ValueError, match="transparency: deep output keeps depth-sorted fragments"):
        render_deep(scene(floor_and_ball()), 8, 8, transparency="weighted_blended")


def test_render_returns_the_deep_frame_on_request():
    s = scene(spheres(list(MATERIALS.values())) + floor_and_ball())
    result = bp.render(s, W, H, transparency="a_buffer", shadows="none", engine="numpy", deep=True)
    np.testing.assert_allclose(flatten(result.deep), result.rgba, rtol=0, atol=1e-6)
    assert bp.render(s, 8, 6, shadows="none", engine="numpy").deep is None
    with pytest.raises(ValueError, match="deep output keeps depth-sorted fragments"):
        bp.render(s, 8, 6, transparency="weighted_blended", shadows="none", engine="numpy", deep=True)


def test_render_rasterizes_once_for_the_flat_and_the_deep_frame(monkeypatch):
    """One pass: the deep image holds the fragments the flat frame's resolve used."""
    calls = []
    rasterize = visibility.rasterize

    def counting(*args, **kwargs):
        calls.append(args[2:4])
        return rasterize(*args, **kwargs)

    monkeypatch.setattr(visibility, "rasterize", counting)
    s = scene(spheres(list(MATERIALS.values())) + floor_and_ball())
    result = bp.render(s, W, H, transparency="a_buffer", shadows="none", engine="numpy", deep=True)
    assert calls == [(W, H)]
    np.testing.assert_allclose(flatten(result.deep), result.rgba, rtol=0, atol=1e-6)
    assert result.stats.seconds["deep"] >= 0


@pytest.mark.parametrize("transparency", ["a_buffer", "depth_peeling"])
def test_deep_frame_in_bands_and_strips(monkeypatch, transparency):
    """Bands of 5 rows and strips of 7 rows (the last ones short) give the deep image of one band,
    and its flatten is the flat frame of the same render."""
    s = scene(spheres(list(MATERIALS.values())) + floor_and_ball())
    kw = dict(transparency=transparency, layers=2 if transparency == "depth_peeling" else None)
    one = bp.render(s, W, H, shadows="none", engine="numpy", deep=True, **kw)
    monkeypatch.setattr(pipeline, "BAND_SAMPLES", W * 5)
    monkeypatch.setattr(pipeline, "STRIP_SAMPLES", W * 7)
    parts = bp.render(s, W, H, shadows="none", engine="numpy", deep=True, **kw)
    np.testing.assert_allclose(flatten(parts.deep), parts.rgba, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(parts.deep.counts, one.deep.counts)
    # Strips rasterize with their own projection: window depths and barycentrics round apart.
    np.testing.assert_allclose(parts.deep.z, one.deep.z, rtol=1e-6, atol=0)
    np.testing.assert_allclose(parts.deep.rgba, one.deep.rgba, rtol=0, atol=2e-6)


def test_supersampled_deep_frame_in_strips_groups_surfaces_per_pixel(monkeypatch):
    """With 2×2 samples, a pixel's subpixels lie in one strip: strips change nothing in the grouping."""
    s = scene(spheres(list(MATERIALS.values())) + floor_and_ball())
    one = bp.render(s, W, H, samples=4, transparency="a_buffer", shadows="none", engine="numpy", deep=True)
    monkeypatch.setattr(pipeline, "STRIP_SAMPLES", W * 4 * 5)
    parts = bp.render(s, W, H, samples=4, transparency="a_buffer", shadows="none", engine="numpy", deep=True)
    np.testing.assert_array_equal(parts.deep.counts, one.deep.counts)
    np.testing.assert_allclose(flatten(parts.deep), flatten(one.deep), rtol=0, atol=2e-6)


@pytest.mark.parametrize("samples", [1, 4])
def test_compiled_deep_frame_flattens_to_the_compiled_flat_frame(samples):
    """The compiled stages: the flat frame of a plain render (the fused resolve) against the
    deep frame of ``render(deep=True)`` (the band path, which keeps fragment colours)."""
    s = scene(spheres(list(MATERIALS.values())) + floor_and_ball())
    kw = dict(transparency="a_buffer", shadows="none", engine="numba", samples=samples, progress=False)
    flat = bp.render(s, W, H, **kw)
    result = bp.render(s, W, H, deep=True, **kw)
    np.testing.assert_allclose(result.rgba, flat.rgba, rtol=0, atol=1e-6)
    if samples == 1:
        np.testing.assert_allclose(flatten(result.deep), flat.rgba, rtol=0, atol=1e-6)
    reference = bp.render(s, W, H, deep=True, **{**kw, "engine": "numpy"})
    np.testing.assert_array_equal(result.deep.counts, reference.deep.counts)
    np.testing.assert_allclose(result.deep.rgba, reference.deep.rgba, rtol=0, atol=1e-5)


def test_a_refused_method_is_refused_before_rasterizing(monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("rasterized")

    monkeypatch.setattr(visibility, "rasterize", fail)
    with pytest.raises(ValueError, match="transparency: deep output keeps depth-sorted fragments"):
        bp.render(scene(floor_and_ball()), 8, 6, transparency="sort_objects", engine="numpy", deep=True)
