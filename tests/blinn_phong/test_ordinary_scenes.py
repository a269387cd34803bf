"""Ordinary scenes at the sizes people render: a sphere on a floor in sunlight, and large frames.

The frame is split into bands of rows (shading) and, above ``STRIP_SAMPLES`` samples, into strips
rendered through every stage. A band or strip with no fragment, or with fragments but no shadowed
one, must render like any other. The references are the numpy engine (an independent
implementation of every stage) and the same frame rendered in one piece.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import blinn_phong as bp
import blinn_phong.frame.pipeline as pipeline
from blinn_phong.frame.resolve import shadow_pass_values
from blinn_phong.model.primitives import grid_plane, uv_sphere

LAY_FLAT = np.array([[1, 0, 0, 0], [0, 0, 1, -1], [0, -1, 0, 0], [0, 0, 0, 1]], float)  # z = 0 → y = -1


def sphere_on_floor(aspect: float) -> bp.Scene:
    """The scene a new user makes first: a sphere over a floor, one sun, sky above the horizon."""
    p, t, n = uv_sphere(32, 16)
    fp, ft, fn = grid_plane(1, 1, size=(4.0, 4.0))
    cam = bp.Camera.perspective(40, aspect, 0.5, 50, view=bp.look_at((0, 0.5, 6), (0, -0.5, 0)))
    return bp.Scene(
        [bp.Mesh(p * 0.5, t, n), bp.Mesh(fp, ft, fn, transform=LAY_FLAT)],
        [bp.DirectionalLight((-0.3, -1, -0.2))],
        cam,
    )


@pytest.mark.parametrize(("width", "height", "samples"), [(640, 480, 4), (1920, 1080, 4), (320, 240, 36)])
def test_sphere_on_floor_renders_at_ordinary_sizes(width: int, height: int, samples: int) -> None:
    result = bp.render(sphere_on_floor(width / height), width, height, samples=samples, progress=False)
    assert result.rgba.shape == (height, width, 4)
    assert np.isfinite(result.rgba).all() and np.isfinite(result.passes["shadow"]).all()
    sky = result.rgba[0, :, 3]  # the top row sees only sky: nothing covers it
    assert (sky == 0).all()
    assert result.passes["shadow"].min() == 0.0  # the sphere's shadow on the floor
    # Downscaled, the numpy engine (an independent implementation) gives the same frame.
    w, h = width // 8, height // 8
    small = sphere_on_floor(w / h)
    fast = bp.render(small, w, h, samples=samples, engine="numba", progress=False)
    ref = bp.render(small, w, h, samples=samples, engine="numpy", progress=False)
    np.testing.assert_allclose(fast.rgba, ref.rgba, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("shape", [(0, 1), (0, 3), (0, 2, 3)])
def test_shadow_pass_of_no_fragment_is_empty(shape: tuple[int, ...]) -> None:
    """A band with no fragment: no values, whatever the light and channel axes."""
    out = shadow_pass_values(np.zeros(shape))
    assert out.shape == (0,)


def test_shadow_pass_is_the_mean_visibility() -> None:
    v = np.random.default_rng(1).uniform(size=(7, 3, 2))
    np.testing.assert_allclose(shadow_pass_values(v), v.reshape(7, -1).mean(axis=1), rtol=1e-15)


def test_strip_camera_maps_strip_rows_to_frame_rows() -> None:
    """A point projected by a strip's camera lands on the strip row of its frame row (closed form)."""
    cam = sphere_on_floor(4 / 3).camera
    height, row0, row1 = 480, 130, 190
    strip = pipeline.strip_camera(cam, height, row0, row1)
    pts = np.random.default_rng(2).uniform(-1, 1, (50, 3))
    hom = np.c_[pts, np.ones(len(pts))]

    def window_y(camera: bp.Camera, rows: int) -> np.ndarray:
        clip = hom @ (camera.projection @ camera.view).T
        return (1 - clip[:, 1] / clip[:, 3]) * rows / 2  # row coordinate from the top

    np.testing.assert_allclose(window_y(strip, row1 - row0), window_y(cam, height) - row0, atol=1e-9)
    clip_a = hom @ (cam.projection @ cam.view).T
    clip_b = hom @ (strip.projection @ strip.view).T
    np.testing.assert_array_equal(clip_a[:, [0, 2, 3]], clip_b[:, [0, 2, 3]])  # x, depth, w unchanged


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"shadows": "shadow_map"},
        {"shadows": "shadow_volume"},
        {"transparency": "a_buffer"},
        {"fog": bp.Fog(mode="linear", start=1.0, end=12.0, color=(0.5, 0.6, 0.7))},
    ],
    ids=["default", "shadow_map", "shadow_volume", "a_buffer", "fog"],
)
def test_frame_in_strips_equals_frame_in_one_piece(monkeypatch: pytest.MonkeyPatch, options: dict) -> None:
    scene = sphere_on_floor(160 / 120)
    if options.get("transparency"):
        glass = bp.Material(diffuse=(0.2, 0.4, 0.9), opacity=0.4)
        p, t, n = uv_sphere(16, 8)
        shift = np.array([[1, 0, 0, 0.6], [0, 1, 0, -0.4], [0, 0, 1, 0.8], [0, 0, 0, 1]], float)
        scene = bp.Scene(
            [*scene.meshes, bp.Mesh(p * 0.4, t, n, transform=shift, material=glass)],
            scene.lights,
            scene.camera,
        )
    whole = bp.render(scene, 160, 120, samples=4, progress=False, **options)
    monkeypatch.setattr(pipeline, "STRIP_SAMPLES", 160 * 4 * 17)  # 17-row strips: 8 strips, the last short
    strips = bp.render(scene, 160, 120, samples=4, progress=False, **options)
    for name in ("rgba", "depth", "normal"):
        np.testing.assert_allclose(
            getattr(strips, name), getattr(whole, name), rtol=0, atol=2e-6, err_msg=name
        )
    for name, p in whole.passes.items():
        np.testing.assert_allclose(strips.passes[name], p, rtol=0, atol=2e-6, err_msg=name)
    assert strips.stats.shaded == whole.stats.shaded


def test_strips_bound_the_frame_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every stage holds one strip's fragments: the traced peak falls with the strip size."""
    scene = sphere_on_floor(240 / 180)
    glass = bp.Material(diffuse=(0.2, 0.4, 0.9), opacity=0.4)
    p, t, n = uv_sphere(16, 8)
    scene = bp.Scene([*scene.meshes, bp.Mesh(p * 0.45, t, n, material=glass)], scene.lights, scene.camera)
    kw = dict(samples=16, progress=False, shadows="ray_traced", transparency="a_buffer")
    bp.render(scene, 24, 18, **kw)  # compile and warm the caches outside the measurement

    def peak() -> int:
        tracemalloc.start()
        bp.render(scene, 240, 180, **kw)
        value = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return value

    monkeypatch.setattr(pipeline, "STRIP_SAMPLES", 1 << 40)
    whole = peak()
    monkeypatch.setattr(pipeline, "STRIP_SAMPLES", 240 * 16 * 20)  # 20-row strips
    strips = peak()
    frame_buffers = 240 * 180 * 17 * 4 * 2  # output images, and the strip's copy
    assert strips < 0.5 * whole, (strips, whole)
    assert strips < frame_buffers + 400 * 240 * 16 * 20, strips


def _glass_scene(aspect: float) -> bp.Scene:
    """The sphere on the floor plus a glass sphere: transparent fragments in some bands only."""
    scene = sphere_on_floor(aspect)
    glass = bp.Material(diffuse=(0.2, 0.4, 0.9), opacity=0.4, specular=(0.5, 0.5, 0.5), shininess=30.0)
    p, t, n = uv_sphere(16, 8)
    shift = np.array([[1, 0, 0, 0.9], [0, 1, 0, -0.6], [0, 0, 1, 0.5], [0, 0, 0, 1]], float)
    lights = [*scene.lights, bp.PointLight((1.5, 1.5, 1.0), linear=0.1)]
    meshes = [*scene.meshes, bp.Mesh(p * 0.35, t, n, transform=shift, material=glass)]
    return bp.Scene(meshes, lights, scene.camera)


@pytest.mark.parametrize(
    "options",
    [
        {"shadows": bp.ShadowOptions(method="planar", plane=(0.0, 1.0, 0.0, 1.0))},
        {"shadows": "shadow_map"},
        {"shadows": "ray_traced"},
        {"shadows": bp.ShadowOptions(method="soft", radius=0.2, samples=4)},
        {"shadows": "shadow_volume"},
        {"transparency": "draw_last"},
        {"transparency": "sort_objects"},
        {"transparency": "sort_triangles"},
        {"transparency": "depth_peeling"},
        {"transparency": "weighted_blended"},
        {"transparency": "a_buffer", "fog": bp.Fog(mode="exp", density=0.05)},
    ],
    ids=lambda o: "-".join(
        str(getattr(v, "method", v if isinstance(v, str) else type(v).__name__)) for v in o.values()
    ),
)
def test_every_method_renders_frames_with_empty_bands(options: dict) -> None:
    """Rows of sky only (no fragment), rows with fragments but no shadow or no glass: every
    shadow and transparency method, in 16-sample bands of 2¹⁹ samples, then downscaled against
    the numpy engine."""
    width, height = 320, 240
    result = bp.render(_glass_scene(width / height), width, height, samples=16, progress=False, **options)
    assert np.isfinite(result.rgba).all() and (result.rgba[0, :, 3] == 0).all()
    w, h = 40, 30
    small = _glass_scene(w / h)
    fast = bp.render(small, w, h, samples=4, engine="numba", progress=False, **options)
    ref = bp.render(small, w, h, samples=4, engine="numpy", progress=False, **options)
    np.testing.assert_allclose(fast.rgba, ref.rgba, rtol=1e-5, atol=1e-5)
