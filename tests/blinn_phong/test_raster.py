"""The rasterizer against closed forms: partitions, pixel-centre counts, ray-plane intersections."""

import numpy as np
import pytest

from blinn_phong.geometry.raster import interpolate, rasterize, resolve_nearest, sample_offsets
from blinn_phong.model.transforms import look_at, perspective_matrix


def _grid_mesh(n: int, jitter: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """An (n+1)² vertex grid over [-1.3, 1.3]² (past the screen), inner vertices jittered, z = 0, w = 1."""
    rng = np.random.default_rng(seed)
    g = np.linspace(-1.3, 1.3, n + 1)
    x, y = np.meshgrid(g, g)
    step = g[1] - g[0]
    inner = (np.abs(x) < 1.3) & (np.abs(y) < 1.3)
    x = x + inner * rng.uniform(-jitter, jitter, x.shape) * step
    y = y + inner * rng.uniform(-jitter, jitter, y.shape) * step
    clip = np.stack([x.ravel(), y.ravel(), np.zeros(x.size), np.ones(x.size)], axis=1)
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    v = (j * (n + 1) + i).ravel()
    tris = np.concatenate([np.stack([v, v + 1, v + n + 2], 1), np.stack([v, v + n + 2, v + n + 1], 1)])
    return clip, tris


@pytest.mark.parametrize("samples", [1, 4])
def test_shared_edges_cover_every_sample_exactly_once(samples: int) -> None:
    # A mesh tiling a region larger than the screen partitions the plane: with a consistent
    # fill rule each sample belongs to exactly one triangle (no cracks, no double hits).
    clip, tris = _grid_mesh(13, 0.35, seed=1)
    # Also snap some vertices onto pixel centres of a 40×30 image to exercise exact ties.
    clip[::7, 0] = (np.floor((clip[::7, 0] + 1) * 20) + 0.5) / 20 - 1
    clip[::5, 1] = (np.floor((clip[::5, 1] + 1) * 15) + 0.5) / 15 - 1
    frags = rasterize(clip, tris, 40, 30, samples=samples)
    hits = np.bincount(frags.sample_key, minlength=40 * 30 * samples)
    assert hits.min() == 1 and hits.max() == 1


def test_axis_aligned_rectangle_follows_the_fill_rule() -> None:
    # Rectangle whose edges pass exactly through pixel centres: columns 2..7 and rows 3..8 have
    # their centres on or inside it. Top-left rule in OpenGL window coordinates (y up, memory
    # order): the left edge (x = 2.5) and the edge with the interior at larger window y (image
    # row 8, the bottom in a top-row-first image) are included; the right and top edges are not.
    w, h = 12, 10
    x_left, x_right = 2.5, 7.5
    row_top, row_bottom = 3.5, 8.5  # from the top
    xs = np.array([x_left, x_right, x_right, x_left]) / w * 2 - 1
    ys = 1 - np.array([row_bottom, row_bottom, row_top, row_top]) / h * 2
    clip = np.stack([xs, ys, np.zeros(4), np.ones(4)], axis=1)
    frags = rasterize(clip, np.array([[0, 1, 2], [0, 2, 3]]), w, h)
    covered = np.zeros(w * h, bool)
    covered[frags.pixel] = True
    expected = np.zeros((h, w), bool)
    expected[4:9, 2:7] = True
    np.testing.assert_array_equal(covered.reshape(h, w), expected)


def _camera_setup() -> tuple[np.ndarray, np.ndarray]:
    view = look_at((0.3, 0.4, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    proj = perspective_matrix(50.0, 1.25, 0.5, 20.0)
    return view, proj


def _pixel_rays(frags, w: int, h: int, view: np.ndarray, proj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-space eye position and unit ray directions through each fragment's sample point."""
    off = sample_offsets(frags.samples)[frags.sample]
    col = frags.pixel % w + off[:, 0]
    row = frags.pixel // w + off[:, 1]
    ndc = np.stack([col / w * 2 - 1, 1 - row / h * 2, np.zeros(len(col)), np.ones(len(col))], axis=1)
    inv = np.linalg.inv(proj @ view)
    far = ndc.copy()
    far[:, 2] = 1
    p0 = ndc @ inv.T
    p1 = far @ inv.T
    p0 = p0[:, :3] / p0[:, 3:]
    p1 = p1[:, :3] / p1[:, 3:]
    eye = np.linalg.inv(view)[:3, 3]
    d = p1 - p0
    return eye, d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("samples", [1, 4])
def test_perspective_correct_barycentrics_match_ray_plane_intersection(samples: int) -> None:
    # Interpolating world positions with the returned barycentrics must give the point where the
    # ray through the sample hits the triangle's plane (exact perspective-correct interpolation),
    # and the window depth must be that point's (z_ndc + 1) / 2.
    w, h = 80, 64
    view, proj = _camera_setup()
    world = np.array([[-1.5, -1.0, -2.0], [1.2, -0.8, 0.5], [0.1, 1.4, -0.7]])
    clip = np.c_[world, np.ones(3)] @ (proj @ view).T
    tris = np.array([[0, 1, 2]])
    frags = rasterize(clip, tris, w, h, samples=samples)
    assert len(frags) > 500
    p = interpolate(frags, tris, world)
    eye, d = _pixel_rays(frags, w, h, view, proj)
    n = np.cross(world[1] - world[0], world[2] - world[0])
    t = ((world[0] - eye) @ n) / (d @ n)
    hit = eye + t[:, None] * d
    # Coverage uses positions snapped to 1/256 pixel, interpolation the exact ones.
    np.testing.assert_allclose(p, hit, atol=1e-9)
    hc = np.c_[hit, np.ones(len(hit))] @ (proj @ view).T
    np.testing.assert_allclose(frags.depth, (hc[:, 2] / hc[:, 3] + 1) / 2, atol=1e-12)
    np.testing.assert_allclose(frags.bary.sum(axis=1), 1.0, atol=1e-12)
    assert (frags.bary > -1e-9).all()


def test_near_plane_clipping_keeps_only_the_visible_part() -> None:
    # One vertex behind the eye: the clipped triangle's fragments all lie in front of the near
    # plane, inside the original triangle, and on the ray through their pixel.
    w, h = 64, 48
    view = np.eye(4)
    near = 0.5
    proj = perspective_matrix(60.0, w / h, near, 50.0)
    world = np.array([[-2.0, -1.0, -4.0], [2.0, -1.0, -4.0], [0.0, -1.0, 3.0]])  # a floor reaching behind
    clip = np.c_[world, np.ones(3)] @ (proj @ view).T
    tris = np.array([[0, 1, 2]])
    frags = rasterize(clip, tris, w, h)
    p = interpolate(frags, tris, world)
    assert (p[:, 2] <= -near + 1e-9).all()
    assert (frags.bary >= -1e-9).all()
    eye, d = _pixel_rays(frags, w, h, view, proj)
    t = (-1.0 - eye[1]) / d[:, 1]
    np.testing.assert_allclose(p, eye + t[:, None] * d, atol=1e-9)
    # Every bottom-row pixel sees the floor (it extends behind the camera), none above the horizon.
    rows = frags.pixel // w
    assert set(frags.pixel[rows == h - 1] % w) == set(range(w))
    assert rows.min() > h // 2


def test_backface_culling_and_facing() -> None:
    clip = np.array([[-0.5, -0.5, 0, 1], [0.5, -0.5, 0, 1], [0, 0.5, 0, 1]], float)
    ccw = np.array([[0, 1, 2]])
    cw = np.array([[0, 2, 1]])
    assert rasterize(clip, ccw, 16, 16).front_facing.all()
    assert not rasterize(clip, cw, 16, 16).front_facing.any()
    assert len(rasterize(clip, cw, 16, 16, cull_backfaces=True)) == 0
    assert len(rasterize(clip, ccw, 16, 16, cull_backfaces=True)) == len(rasterize(clip, ccw, 16, 16))


def test_resolve_nearest_takes_smaller_depth_then_draw_order() -> None:
    quad = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
    clip = np.concatenate(
        [np.c_[quad, np.full(4, z), np.ones(4)] for z in (0.5, -0.25, -0.25)]  # far, near, near again
    )
    tris = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [8, 9, 10], [8, 10, 11]])
    frags = rasterize(clip, tris, 8, 8)
    win = resolve_nearest(frags)
    assert (win >= 0).all()
    assert set(frags.triangle[win]) == {2, 3}  # the near quad drawn first
    np.testing.assert_allclose(frags.depth[win], (-0.25 + 1) / 2)


def test_zero_area_and_offscreen_triangles_make_no_fragments() -> None:
    clip = np.array(
        [[0, 0, 0, 1], [0.5, 0.5, 0, 1], [1, 1, 0, 1], [3, 3, 0, 1], [4, 3, 0, 1], [3, 4, 0, 1]], float
    )
    frags = rasterize(clip, np.array([[0, 1, 2], [3, 4, 5]]), 16, 16)
    assert len(frags) == 0
    assert (resolve_nearest(frags) == -1).all()


@pytest.mark.parametrize(
    ("clip", "tris", "size", "samples", "match"),
    [
        (np.zeros((3, 3)), [[0, 1, 2]], 8, 1, "clip_xyzw"),
        (np.full((3, 4), np.nan), [[0, 1, 2]], 8, 1, "NaN"),
        (np.ones((3, 4)), [[0, 1, 3]], 8, 1, "triangles"),
        (np.ones((3, 4)), [[0.0, 1.0, 2.0]], 8, 1, "integer"),
        (np.ones((3, 4)), [[0, 1, 2]], 0, 1, "width"),
        (np.ones((3, 4)), [[0, 1, 2]], 8, 3, "perfect square"),
    ],
)
def test_bad_input_is_rejected_with_a_clear_message(clip, tris, size, samples, match) -> None:
    with pytest.raises((ValueError, TypeError), match=match):
        rasterize(clip, np.asarray(tris), size, 8, samples=samples)
