"""Shadow maps looked up inside the fused shading kernel (:mod:`blinn_phong.shadows.frame_maps`).

When every shadowed light of an opaque one-sample frame uses a shadow map, the fused kernel
looks each pixel's world point up itself, and a point light's cube is rendered only over the
texels the *visible triangles* can be looked up in. Checked here:

* the rectangles of :func:`blinn_phong.shadows.map_receiver_kernels.receiver_triangle_rects` hold every
  texel that a look-up of any point on the triangles reads — recomputed with numpy from the
  formulas of :func:`blinn_phong.shadows.maps.shadow_visibility` (``_reference_taps``) at random
  points of the triangles, their corners and edges, for triangles inside one face's cone,
  across the borders of several faces, and passing next to the light;
* the frame equals, bit for bit, the general path (each pixel's world point written, then
  :func:`blinn_phong.shadows.methods.light_visibility` per light, then the kernel reads the
  visibilities): the same points, the same maps wherever a look-up reads, the same
  operations per look-up, the same shadow-pass sum — deterministic by construction (no
  threaded reduction), for every light type, the PCF kernels, the biases, unshadowed
  lights, flat shading and fog;
* the stack's memory is reused between frames and bounded (:class:`blinn_phong._scratch.ScratchPool`).
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong._scratch import ScratchPool, carve, carved_bytes
from blinn_phong.shadows.maps import light_cameras

from .test_shadow_kernels import SCENE  # the shadow-kernel tests' casters
from .test_shadow_receiver_maps import POINT, RES, _reference_taps

pytest.importorskip("numba")

from blinn_phong.frame import pipeline
from blinn_phong.shadows import frame_maps  # imports numba
from blinn_phong.shadows.map_receiver_kernels import receiver_triangle_rects


def _triangles_around_the_light(rng: np.random.Generator) -> np.ndarray:
    """Receiver triangles: some of the scene's, big ones around the light crossing the borders of
    several cube faces, and thin ones passing within 1e-4 of the light."""
    light = np.asarray(POINT.position)
    picked = SCENE[rng.choice(len(SCENE), 60, replace=False)]
    big = []
    for _ in range(12):
        centre = light + rng.normal(size=3) * 0.5
        big.append(centre + rng.normal(size=(3, 3)) * 2.0)
    near = []
    for _ in range(4):
        a = light + rng.normal(size=3) * 1e-4
        near.append(np.stack([a, a + rng.normal(size=3), a + rng.normal(size=3)]))
    return np.concatenate([picked, np.array(big), np.array(near)])


def _points_on(triangles: np.ndarray, rng: np.random.Generator, per: int) -> np.ndarray:
    """Random points of every triangle, with its corners and edge midpoints, interpolated as the
    rasterizer interpolates (Σ b_k·v_k in float64)."""
    b = rng.dirichlet((1.0, 1.0, 1.0), size=(len(triangles), per))
    fixed = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, 0.5, 0], [0, 0.5, 0.5], [0.5, 0, 0.5]], float)
    b = np.concatenate([b, np.broadcast_to(fixed, (len(triangles), 6, 3))], axis=1)
    return np.einsum("tpk,tkc->tpc", b, triangles).reshape(-1, 3)


@pytest.mark.parametrize("kernel", ["nearest", "bilinear", "box5"])
def test_triangle_rectangles_hold_every_texel_a_point_of_the_triangles_reads(kernel: str) -> None:
    rng = np.random.default_rng(11)
    triangles = _triangles_around_the_light(rng)
    cameras = light_cameras(POINT, SCENE)
    vps = np.stack([proj @ view for view, proj in cameras])
    rects = receiver_triangle_rects(triangles, vps, np.asarray(POINT.position), RES, kernel)
    points = _points_on(triangles, rng, 400)
    taps = _reference_taps(POINT, points, np.zeros_like(points), kernel, 0.0)
    assert len(np.unique(taps[:, 0])) == 6  # the big triangles reach every face
    for f in range(6):
        mine = taps[taps[:, 0] == f]
        r0, r1, c0, c1 = rects[f]
        assert r0 <= mine[:, 1].min() and mine[:, 1].max() <= r1, f
        assert c0 <= mine[:, 2].min() and mine[:, 2].max() <= c1, f


def test_triangle_rectangles_are_tight_for_a_small_patch() -> None:
    # a small patch of ground inside one face: its rectangle is the patch's, not the face
    patch = np.array(
        [
            [[1.0, -0.8, 0.0], [2.2, -0.8, 0.0], [2.2, 0.4, 0.0]],
            [[1.0, -0.8, 0.0], [2.2, 0.4, 0.0], [1.0, 0.4, 0.0]],
        ]
    )
    cameras = light_cameras(POINT, SCENE)
    vps = np.stack([proj @ view for view, proj in cameras])
    rects = receiver_triangle_rects(patch, vps, np.asarray(POINT.position), RES, "nearest")
    read = [f for f in range(6) if rects[f, 0] <= rects[f, 1]]
    assert read == [5]  # the −z face only
    rng = np.random.default_rng(2)
    points = _points_on(patch, rng, 2000)
    taps = _reference_taps(POINT, points, np.zeros_like(points), "nearest", 0.0)
    r0, r1, c0, c1 = rects[5]
    assert r0 >= taps[:, 1].min() - 5 and r1 <= taps[:, 1].max() + 5  # the margin, no more
    assert c0 >= taps[:, 2].min() - 5 and c1 <= taps[:, 2].max() + 5


def _scene(light_at_the_border: bool = False) -> bp.Scene:
    from blinn_phong.model.primitives import grid_plane, uv_sphere

    pos, tris, normals = uv_sphere(24, 12)
    meshes = []
    for i, x in enumerate((-0.9, 0.9)):
        t = np.eye(4)
        t[:3, 3] = (x, 0.0, 0.8 + 0.3 * i)
        material = bp.Material(diffuse=(0.8, 0.3 + 0.4 * i, 0.2), specular=(0.5, 0.5, 0.5), shininess=30.0)
        meshes.append(bp.Mesh(pos, tris, normals, transform=t, material=material))
    plane, ptris, pnormals = grid_plane(3, 3, (8.0, 8.0))
    meshes.append(bp.Mesh(plane, ptris, pnormals, material=bp.Material(diffuse=(0.6, 0.6, 0.6))))
    # a point light low over the ground: the cube's face borders cross the visible ground
    point = (0.1, -0.2, 0.6) if light_at_the_border else (1.5, -1.5, 3.5)
    lights = (
        bp.DirectionalLight((0.3, 0.4, -1.0)),
        bp.PointLight(point, quadratic=0.05),
        bp.SpotLight((0.0, -3.0, 3.0), (0.0, 0.8, -0.6), 35.0, 6.0),
        bp.AmbientLight((0.1, 0.1, 0.1)),
    )
    camera = bp.Camera.perspective(
        50.0, 4 / 3, 0.3, 30.0, view=bp.look_at((0.5, -5.0, 2.5), (0, 0, 0.6), (0, 0, 1))
    )
    return bp.Scene(tuple(meshes), lights, camera)


MAP = {"resolution": 256}
FRAMES = [
    ({"shadows": bp.ShadowOptions("shadow_map", **MAP)}, False),
    ({"shadows": bp.ShadowOptions("shadow_map", **MAP)}, True),
    ({"shadows": bp.ShadowOptions("shadow_map", kernel="box3", **MAP)}, True),
    ({"shadows": bp.ShadowOptions("shadow_map", kernel="bilinear", **MAP)}, False),
    ({"shadows": bp.ShadowOptions("shadow_map", kernel="box5", constant_bias=1e-3, **MAP)}, False),
    (
        {
            "shadows": [
                bp.ShadowOptions("shadow_map", **MAP),
                "none",
                bp.ShadowOptions("shadow_map", kernel="box3", **MAP),
                "none",
            ]
        },
        True,
    ),
    ({"shadows": bp.ShadowOptions("shadow_map", **MAP), "shading": "flat"}, False),
    (
        {
            "shadows": bp.ShadowOptions("shadow_map", **MAP),
            "fog": bp.Fog("exp", (0.5, 0.6, 0.7), density=0.1),
        },
        True,
    ),
]


@pytest.mark.parametrize(("options", "border"), FRAMES, ids=range(len(FRAMES)))
def test_in_kernel_look_ups_equal_the_general_path(
    options: dict, border: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    scene = _scene(border)
    stacks: list[object] = []
    original = frame_maps.frame_maps
    monkeypatch.setattr(frame_maps, "frame_maps", lambda *a: stacks.append(a) or original(*a))
    general_calls: list[object] = []
    general_path = pipeline._winner_visibility
    monkeypatch.setattr(
        pipeline, "_winner_visibility", lambda *a: general_calls.append(a) or general_path(*a)
    )
    fused = bp.render(scene, 160, 120, **options)
    assert len(stacks) == 1 and general_calls == []  # looked up in the kernel, every tap rendered
    monkeypatch.setattr(pipeline, "_IN_KERNEL_MAPS", False)
    general = bp.render(scene, 160, 120, **options)
    assert len(stacks) == 1
    assert fused.plan.shadows == general.plan.shadows
    shadow = general.passes["shadow"]
    assert 0.05 < float((shadow[..., 0] < 0.99 * general.rgba[..., 3]).mean()) < 0.9  # shadows in view
    np.testing.assert_array_equal(fused.rgba, general.rgba)  # bitwise: see the module docstring
    for name in general.passes:
        np.testing.assert_array_equal(fused.passes[name], general.passes[name], err_msg=name)
    np.testing.assert_array_equal(fused.depth, general.depth)
    np.testing.assert_array_equal(fused.normal, general.normal)


def test_a_light_at_the_border_reads_several_faces() -> None:
    # the case above whose cube faces meet in view: the visible triangles reach four faces
    scene = _scene(True)
    prepared = bp.prepare_scene(scene)
    from blinn_phong.geometry.raster_kernels import nearest_winners_compiled, setup_triangles_compiled

    setup = setup_triangles_compiled(prepared.clip, prepared.triangles, 160, 120, 1, False)
    winner = nearest_winners_compiled(setup)
    seen = frame_maps.visible_triangles(winner, setup.source, len(prepared.triangles))
    assert 0 < len(seen) < len(prepared.triangles)
    np.testing.assert_array_equal(seen, np.unique(setup.source[winner[winner >= 0]]))
    verts = pipeline._all_world_vertices(scene)
    light = scene.lights[1]
    tris = pipeline._world_triangles(scene)
    vps = np.stack([p @ v for v, p in light_cameras(light, tris)])
    rects = receiver_triangle_rects(
        verts[prepared.triangles[seen]], vps, np.asarray(light.position), 256, "nearest"
    )
    assert sum(rects[f, 0] <= rects[f, 1] for f in range(6)) >= 4


def test_mixed_methods_and_resolutions_take_the_general_path(monkeypatch: pytest.MonkeyPatch) -> None:
    scene = _scene()
    called: list[object] = []
    original = frame_maps.frame_maps
    monkeypatch.setattr(frame_maps, "frame_maps", lambda *a: called.append(a) or original(*a))
    sm = bp.ShadowOptions("shadow_map", resolution=128)
    bp.render(scene, 64, 48, shadows=[sm, "ray_traced", sm, "none"])
    bp.render(scene, 64, 48, shadows=[sm, bp.ShadowOptions("shadow_map", resolution=64), sm, "none"])
    assert called == []


def test_frame_maps_checks_its_lights() -> None:
    light = _scene().lights[0]
    with pytest.raises(ValueError, match="lit\\[0\\]: expected a shadow_map"):
        with frame_maps.frame_maps([(light, "ray_traced", {})], SCENE, SCENE[:2]):
            pass
    with pytest.raises(ValueError, match="one resolution"):
        lit = [(light, "shadow_map", {"resolution": 64}), (POINT, "shadow_map", {"resolution": 32})]
        with frame_maps.frame_maps(lit, SCENE, SCENE[:2]):
            pass
    with pytest.raises(ValueError, match="kernel must be one of"):
        with frame_maps.frame_maps([(light, "shadow_map", {"kernel": "gauss"})], SCENE, SCENE[:2]):
            pass


def test_the_scratch_pool_reuses_and_bounds_its_buffers() -> None:
    pool = ScratchPool(max_bytes=1 << 20, keep=1)
    with pool.bytes(1000) as a:
        address = a.ctypes.data
    with pool.bytes(800) as b:  # the kept buffer, its pages already mapped
        assert b.ctypes.data == address and len(b) == 800
        with pool.bytes(800) as c:  # taken: a new one
            assert c.ctypes.data != address
    with pool.bytes(2 << 20) as big:  # over max_bytes: freed after use, never kept
        pass
    with pool.bytes(10) as d:
        assert d.ctypes.data != big.ctypes.data
    parts = (((3, 5), np.float64), ((7,), np.int32), ((2, 2), np.int64))
    assert carved_bytes(*parts) == 120 + 32 + 32  # each part starts on 8 bytes
    with pool.bytes(carved_bytes(*parts)) as buf:
        x, y, z = carve(buf, *parts)
        x[:] = 1.5
        y[:] = -2
        z[:] = 7
        assert x.shape == (3, 5) and y.dtype == np.int32 and z.flags.c_contiguous
        assert (x == 1.5).all() and (y == -2).all() and (z == 7).all()  # disjoint
    with pytest.raises(ValueError, match="max_bytes and keep"):
        ScratchPool(-1)


def test_a_look_up_outside_the_rendered_texels_shades_the_frame_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # rectangles cut to their upper half: the look-ups of the lower half leave them, the kernel
    # says so, and the frame is shaded again from the general path's visibilities
    def halved(*args: object) -> np.ndarray:
        rects = receiver_triangle_rects(*args)  # type: ignore[arg-type]
        rects[:, 1] = np.where(rects[:, 0] <= rects[:, 1], (rects[:, 0] + rects[:, 1]) // 2, rects[:, 1])
        return rects

    scene = _scene(True)
    options = {"shadows": bp.ShadowOptions("shadow_map", **MAP)}
    general_calls: list[object] = []
    general_path = pipeline._winner_visibility
    monkeypatch.setattr(
        pipeline, "_winner_visibility", lambda *a: general_calls.append(a) or general_path(*a)
    )
    monkeypatch.setattr(frame_maps, "receiver_triangle_rects", halved)
    fused = bp.render(scene, 160, 120, **options)
    assert len(general_calls) == 1  # the miss was seen
    monkeypatch.setattr(pipeline, "_IN_KERNEL_MAPS", False)
    general = bp.render(scene, 160, 120, **options)
    np.testing.assert_array_equal(fused.rgba, general.rgba)
    np.testing.assert_array_equal(fused.passes["shadow"], general.passes["shadow"])


def test_release_scratch_returns_the_memory_kept_between_frames() -> None:
    bp.render(_scene(), 64, 48, shadows=bp.ShadowOptions("shadow_map", resolution=64))
    kept = frame_maps._DEPTH_SCRATCH.max_bytes  # (a bound, not the size)
    freed = bp.release_scratch()
    # the depth stack (eight 64² maps: directional, spot, six cube faces) and the set-up
    # records (a slot per map and triangle) were kept, and are gone
    assert 64 * 64 * 8 < freed < 2 * kept
    assert bp.release_scratch() == 0
