"""Cube shadow maps rendered only where the receivers look them up.

``light_visibility("shadow_map")`` with the compiled engine renders no cube face that no
receiver uses, and the others only over a rectangle holding every texel the receivers' look-ups
read (:func:`blinn_phong.shadows.map_receiver_kernels.receiver_visibility_compiled`; a single map, directional
or spot, is rendered whole by the same kernels, and checked here too). A texel's depth is the
minimum over the triangles covering it — the same whether or not its neighbours are rendered —
and each look-up reads only texels inside its face's rectangle, so:

* the visibilities equal, bit for bit, those looked up in the complete maps
  (:func:`light_shadow_maps` then :func:`shadow_map_visibility`, both compiled). This is
  deterministic by construction: the same double-precision operations per texel and per point,
  a minimum that does not depend on the drawing order, no threaded reduction;
* they agree with the numpy reference (:mod:`blinn_phong.shadows.maps`) as the other compiled
  kernels do (1e-9; tests/effects/test_shadow_kernels.py explains the bound);
* the rectangles hold every texel the reference's taps read: recomputed here with numpy from
  the formulas of :func:`blinn_phong.shadows.maps.shadow_visibility` (face of the major axis, normal
  offset, projection, the taps of each kernel clamped to the map).
"""

import numpy as np
import pytest

from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.shadows.maps import PCF_KERNELS, light_cameras, light_shadow_maps, shadow_map_visibility
from blinn_phong.shadows.methods import light_visibility

from .test_shadow_kernels import SCENE, surface_samples  # the shadow-kernel tests' scene

pytest.importorskip("numba")

POINT = PointLight((0.5, 1.5, 2.5))
RES = 96
BIAS = {"constant_bias": 1e-4, "slope_bias": 3.0}


def _cube_face(points: np.ndarray, light_position: np.ndarray) -> np.ndarray:
    """The cube face (index into _CUBE_FACES) of each point: its major axis, ties to the lower axis."""
    rel = points - light_position
    axis = np.argmax(np.abs(rel), axis=1)
    negative = rel[np.arange(len(rel)), axis] < 0
    return 2 * axis + negative


def _receivers(keep: str) -> tuple[np.ndarray, np.ndarray]:
    points, normals = surface_samples(SCENE, 6000, seed=5)
    if keep == "below":  # the point light's −z face and parts of the side faces
        sel = points[:, 2] < 0.5
    elif keep == "patch":  # a small patch of ground next to the sphere: a small rectangle of a map
        u, v = np.meshgrid(np.linspace(1.0, 2.2, 40), np.linspace(-0.8, 0.4, 40))
        patch = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1)
        return patch, np.tile([0.0, 0.0, 1.0], (len(patch), 1))
    elif keep == "one_face":  # only points whose major axis is −z
        sel = _cube_face(points, np.asarray(POINT.position)) == 5
    else:
        sel = np.ones(len(points), bool)
    return np.ascontiguousarray(points[sel]), np.ascontiguousarray(normals[sel])


def _full_maps_visibility(light, points, normals, kernel, normal_offset, engine):
    maps = light_shadow_maps(light, SCENE, RES, engine=engine, **BIAS)
    return shadow_map_visibility(
        light, maps, points, normals, normal_offset=normal_offset, kernel=kernel, engine=engine
    )


LIGHTS = {
    "point": POINT,
    "directional": DirectionalLight((-0.5, -0.3, -1.0)),
    "spot": SpotLight((1.0, 0.5, 3.0), (-0.3, -0.15, -1.0), 60.0),
    "wide_spot": SpotLight((1.0, 0.5, 3.0), (-0.3, -0.15, -1.0), 85.0),  # a cube, as a point light
}


@pytest.mark.parametrize("kind", list(LIGHTS))
@pytest.mark.parametrize("keep", ["all", "below", "patch", "one_face"])
@pytest.mark.parametrize(("kernel", "normal_offset"), [("nearest", 0.0), ("bilinear", 0.02), ("box7", 0.0)])
def test_receiver_maps_equal_complete_maps_and_the_reference(kind, keep, kernel, normal_offset):
    light = LIGHTS[kind]
    points, normals = _receivers(keep)
    assert len(points) > 100
    got = light_visibility(
        "shadow_map", light, SCENE, points, normals, resolution=RES, kernel=kernel,
        normal_offset=normal_offset, engine="numba", **BIAS,
    )  # fmt: skip
    full = _full_maps_visibility(light, points, normals, kernel, normal_offset, "numba")
    np.testing.assert_array_equal(got, full)
    ref = _full_maps_visibility(light, points, normals, kernel, normal_offset, "numpy")
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9)
    assert 0.01 < 1 - ref.mean() < 0.99  # shadowed and lit receivers both present


def test_the_point_light_cases_leave_cube_faces_unused():
    """The receiver sets above do leave faces of the point light's cube without a look-up."""
    position = np.asarray(POINT.position)
    used = {keep: set(_cube_face(_receivers(keep)[0], position).tolist()) for keep in ("below", "one_face")}
    assert used["one_face"] == {5}
    assert 1 < len(used["below"]) < 6


def _reference_taps(light, points, normals, kernel, normal_offset):
    """(face, row, column) of every texel the reference look-up reads (shadow_visibility's formulas)."""
    cameras = light_cameras(light, SCENE)
    if len(cameras) == 6:
        face = _cube_face(points, np.asarray(light.position))
    else:
        face = np.zeros(len(points), np.int64)
    taps = []
    for f, (view, projection) in enumerate(cameras):
        sel = face == f
        p, n = points[sel], normals[sel]
        if normal_offset:
            n = n / np.linalg.norm(n, axis=1, keepdims=True)
            n = np.where(((n @ view[:3, :3].T)[:, 2] < 0)[:, None], -n, n)
            p = p + normal_offset * n
        clip = np.c_[p, np.ones(len(p))] @ (projection @ view).T
        w = clip[:, 3]
        front = w > 0
        ndc = clip[:, :3] / np.where(front, w, 1.0)[:, None]
        x = (ndc[:, 0] + 1) * 0.5 * RES
        y = RES - (ndc[:, 1] + 1) * 0.5 * RES
        z = (ndc[:, 2] + 1) * 0.5
        inside = front & (np.abs(ndc[:, 0]) <= 1) & (np.abs(ndc[:, 1]) <= 1) & (z <= 1)
        x, y = x[inside], y[inside]
        if kernel == "nearest":
            offsets, cols, rows = [(0, 0)], np.floor(x), np.floor(y)
        elif kernel == "bilinear":
            offsets, cols, rows = [(0, 0), (1, 0), (0, 1), (1, 1)], np.floor(x - 0.5), np.floor(y - 0.5)
        else:
            h = (int(kernel[3:]) - 1) // 2
            offsets = [(ox, oy) for oy in range(-h, h + 1) for ox in range(-h, h + 1)]
            cols, rows = np.floor(x), np.floor(y)
        for ox, oy in offsets:
            c = np.clip(cols + ox, 0, RES - 1).astype(np.int64)
            r = np.clip(rows + oy, 0, RES - 1).astype(np.int64)
            taps.append(np.stack([np.full(len(c), f), r, c], axis=1))
    return np.concatenate(taps) if taps else np.zeros((0, 3), np.int64)


@pytest.mark.parametrize("kind", ["point", "wide_spot"])
@pytest.mark.parametrize("kernel", PCF_KERNELS)
@pytest.mark.parametrize("normal_offset", [0.0, 0.05])
def test_receiver_rectangles_hold_every_texel_the_reference_reads(kind, kernel, normal_offset):
    from blinn_phong.shadows.map_lookup_kernels import KERNEL_CODES
    from blinn_phong.shadows.map_receiver_kernels import _receiver_rects

    light = LIGHTS[kind]
    points, normals = _receivers("below")
    cameras = light_cameras(light, SCENE)
    assert len(cameras) == 6
    vps = np.stack([proj @ view for view, proj in cameras])
    view_z = np.ascontiguousarray(np.stack([view[2, :3] for view, _ in cameras]))
    position = np.asarray(light.position, dtype=np.float64)
    faces = np.empty(len(points), np.int8)
    rects = _receiver_rects(
        points, normals, 6, RES, vps, view_z, 1, position, normal_offset, KERNEL_CODES[kernel], 4, faces
    )
    np.testing.assert_array_equal(faces, _cube_face(points, position))  # handed to the look-up
    taps = _reference_taps(light, points, normals, kernel, normal_offset)
    assert len(taps) > 100
    for f in range(len(cameras)):
        mine = taps[taps[:, 0] == f]
        r0, r1, c0, c1 = rects[f]
        if len(mine) == 0:
            assert r0 > r1  # a face no receiver reads is not rendered
            continue
        assert r0 <= mine[:, 1].min() and mine[:, 1].max() <= r1
        assert c0 <= mine[:, 2].min() and mine[:, 2].max() <= c1
        # bounded from outside by a few texels only: the margin, not a whole map
        assert mine[:, 1].min() - r0 <= 5 and r1 - mine[:, 1].max() <= 5
        assert mine[:, 2].min() - c0 <= 5 and c1 - mine[:, 2].max() <= 5
    assert any(rects[f, 0] > rects[f, 1] for f in range(6))  # "below" leaves a face unread


def test_no_receiver_and_receivers_outside_every_map_are_lit():
    none = np.zeros((0, 3))
    empty = light_visibility("shadow_map", POINT, SCENE, none, none, resolution=RES, engine="numba")
    assert empty.shape == (0,)
    # far outside the directional map's bounding sphere (and at the point light itself: no face)
    far = np.array([[50.0, 50.0, 50.0], [-60.0, 10.0, 3.0], list(POINT.position)])
    normals = np.tile([0.0, 0.0, 1.0], (3, 1))
    for light in (LIGHTS["directional"], LIGHTS["spot"], POINT):
        vis = light_visibility("shadow_map", light, SCENE, far, normals, resolution=RES, engine="numba")
        ref = light_visibility("shadow_map", light, SCENE, far, normals, resolution=RES, engine="numpy")
        np.testing.assert_array_equal(vis, ref)
    np.testing.assert_array_equal(
        light_visibility("shadow_map", LIGHTS["directional"], SCENE, far[:2], normals[:2], engine="numba"),
        np.ones(2),
    )
