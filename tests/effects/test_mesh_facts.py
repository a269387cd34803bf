"""The planner's mesh facts (closed, convex, planar, bounds) against independent sources.

Convexity is checked against its global definition — every triangle's plane has every vertex
on or below it and the surface is closed — evaluated by brute force over all vertex–plane
pairs, and against :class:`scipy.spatial.ConvexHull` (Qhull: a convex closed surface encloses
the hull's volume). Closedness against meshes built by hand (open, non-manifold, inconsistently
wound) and Euler's formula ``V − E + F = 2 − 2g`` on the edge rows the compiled pass builds.
The compiled passes and the numpy reference give the same decisions on every mesh.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from blinn_phong.geometry import mesh_facts as mf
from blinn_phong.model.primitives import grid_plane, uv_sphere
from blinn_phong.model.scene import Mesh

needs_numba = pytest.mark.skipif(mf._kernels() is None, reason="numba is not installed")


@pytest.fixture(autouse=True)
def compiled_for_every_size(monkeypatch):
    """Small meshes use the compiled passes too, whether numba is loaded yet or not."""
    monkeypatch.setattr(mf, "_COMPILED_FROM", 0)


def hull_mesh(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The convex hull's triangles (Qhull), wound counter-clockwise seen from outside."""
    hull = ConvexHull(points)
    tris = hull.simplices.copy()
    p0, p1, p2 = (points[tris[:, k]] for k in range(3))
    outward = np.einsum("ij,ij->i", np.cross(p1 - p0, p2 - p0), hull.equations[:, :3]) > 0
    tris[~outward] = tris[~outward][:, [0, 2, 1]]
    return points, tris


def globally_convex(points: np.ndarray, tris: np.ndarray, tol: float) -> bool:
    """The definition: every vertex on or below every triangle's outward plane (brute force)."""
    p0, p1, p2 = (points[tris[:, k]] for k in range(3))
    n = np.cross(p1 - p0, p2 - p0)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    heights = points @ n.T - np.einsum("ij,ij->i", n, p0)
    return bool(heights.max() <= tol)


def signed_volume(points: np.ndarray, tris: np.ndarray) -> float:
    p0, p1, p2 = (points[tris[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", p0, np.cross(p1, p2)).sum() / 6.0)


def both(points: np.ndarray, tris: np.ndarray) -> tuple[bool, bool]:
    """``(closed, convex)`` from the compiled pass, asserting the numpy reference agrees."""
    tol = mf.coordinate_tolerance(points[np.unique(tris)])
    compiled = mf._convex_surface(points, tris, tol)
    reference = mf._convex_surface_numpy(points, tris, tol)
    assert compiled == reference, (compiled, reference)
    return compiled


def torus(n_major: int = 24, n_minor: int = 12) -> tuple[np.ndarray, np.ndarray]:
    u, v = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a, b = 2 * np.pi * u.ravel() / n_major, 2 * np.pi * v.ravel() / n_minor
    r = 1.0 + 0.3 * np.cos(b)
    points = np.stack([r * np.cos(a), r * np.sin(a), 0.3 * np.sin(b)], axis=1)

    def idx(i, j):
        return (i % n_major) * n_minor + (j % n_minor)

    tris = []
    for i in range(n_major):
        for j in range(n_minor):
            tris += [
                [idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)],
                [idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)],
            ]
    tris = np.array(tris)
    if signed_volume(points, tris) < 0:
        tris = tris[:, [0, 2, 1]]
    return points, tris


def cone(segments: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed cone: apex and base centre each of degree ``segments`` (long edge rows)."""
    a = 2 * np.pi * np.arange(segments) / segments
    points = np.r_[[[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]], np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], 1)]
    s = np.arange(segments)
    ring, nxt = 2 + s, 2 + (s + 1) % segments
    tris = np.r_[np.stack([np.zeros_like(s), ring, nxt], 1), np.stack([np.ones_like(s), nxt, ring], 1)]
    return points, tris


def undirected_edges(tris: np.ndarray, n_vertices: int) -> int:
    """Edges counted from the compiled rows of out-neighbours: each unordered pair once."""
    k = mf._kernels()
    _, start, dst = k["rows"](np.ascontiguousarray(tris, dtype=np.int64), n_vertices)
    src = np.repeat(np.arange(n_vertices), np.diff(start))
    return len({(min(a, b), max(a, b)) for a, b in zip(src.tolist(), dst.tolist(), strict=True)})


@needs_numba
@pytest.mark.parametrize("seed", range(6))
def test_random_hulls_are_closed_and_convex_and_dents_are_caught(seed):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(60 + 40 * seed, 3)) * rng.uniform(0.2, 3.0, size=3) + rng.normal(size=3) * 5
    points, tris = hull_mesh(points)
    tol = mf.coordinate_tolerance(points)
    assert globally_convex(points, tris, tol)
    assert signed_volume(points, tris) == pytest.approx(ConvexHull(points).volume, rel=1e-9)
    assert both(points, tris) == (True, True)
    # Euler: a closed genus-0 surface has V − E + F = 2 (E from the compiled edge rows)
    used = np.unique(tris)
    assert len(used) - undirected_edges(tris, len(points)) + len(tris) == 2
    # inside-out winding: closed, not convex (normals point inwards)
    assert both(points, tris[:, [0, 2, 1]]) == (True, False)
    # dent hull vertices towards the centroid: the decision follows the global definition
    verdicts = []
    for v in rng.choice(used, size=8, replace=False):
        dented = points.copy()
        dented[v] = dented[v] + 0.5 * (points[used].mean(axis=0) - dented[v])
        expected = globally_convex(dented, tris, mf.coordinate_tolerance(dented))
        hull_volume = ConvexHull(dented[used]).volume
        assert expected == (abs(signed_volume(dented, tris) - hull_volume) <= 1e-9 * hull_volume)
        assert both(dented, tris) == (True, expected)
        verdicts.append(expected)
    assert not all(verdicts)  # the dents do make some of them non-convex


@needs_numba
def test_closedness_of_hand_built_meshes():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    tet = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])  # outward winding
    assert signed_volume(points, tet) > 0
    assert both(points, tet) == (True, True)
    assert len(points) - undirected_edges(tet, 4) + len(tet) == 2  # 4 − 6 + 4
    assert both(points, tet[:3]) == (False, False)  # a face missing: open
    flipped = tet.copy()
    flipped[3] = flipped[3][[0, 2, 1]]
    assert both(points, flipped) == (False, False)  # inconsistent winding: an edge occurs twice
    assert both(points, np.r_[tet, tet[:1]]) == (False, False)  # a face twice: non-manifold
    # two tetrahedra sharing one edge (0, 1): that edge has four faces — not a closed 2-manifold
    other = np.array([[0.0, 0, 0], [1, 0, 0], [0, -1, 0], [0, 0, -1]])
    pair = np.r_[points, other[2:]]
    second = np.array([[0, 1, 4], [0, 4, 5], [0, 5, 1], [1, 5, 4]])
    if signed_volume(pair, second) < 0:
        second = second[:, [0, 2, 1]]
    assert both(pair, second) == (True, True)
    assert both(pair, np.r_[tet, second]) == (False, False)
    # a degenerate (loop) edge
    assert both(points, np.r_[tet, [[0, 0, 1]]]) == (False, False)


@needs_numba
def test_a_torus_is_closed_with_euler_characteristic_zero_and_not_convex():
    points, tris = torus()
    assert both(points, tris) == (True, False)
    assert len(points) - undirected_edges(tris, len(points)) + len(tris) == 0  # genus 1


@needs_numba
@pytest.mark.parametrize("segments", [8, 40, 200])
def test_cones_with_high_degree_vertices(segments):
    points, tris = cone(segments)  # apex and base centre: rows of `segments` entries
    assert globally_convex(points, tris, mf.coordinate_tolerance(points))
    assert both(points, tris) == (True, True)
    assert len(points) - undirected_edges(tris, len(points)) + len(tris) == 2
    assert both(points, np.r_[tris, tris[:1]]) == (False, False)  # one apex face twice
    assert both(points, tris[1:]) == (False, False)
    low = points.copy()
    low[0, 2] = -0.5  # apex below the base: inside-out half, not convex
    assert both(low, tris)[1] is False


@needs_numba
def test_welding_split_vertices_matches_the_reference():
    # a cube with 4 vertices per face (24 vertices) welds into the closed, convex cube
    corners = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    closed_cube, cube_tris = hull_mesh(corners + np.random.default_rng(0).normal(size=(8, 3)) * 1e-3)
    split = closed_cube[cube_tris].reshape(-1, 3)  # a triangle soup: 36 vertices
    soup = np.arange(len(split)).reshape(-1, 3)
    assert both(split, soup) == (True, True)
    assert both(split, soup[:-1]) == (False, False)
    # the hash table and numpy's sort weld the same vertices together
    rng = np.random.default_rng(1)
    cells = rng.integers(-3, 3, size=(500, 3)).astype(np.int64)
    label, welded = mf._kernels()["weld"](cells, cells.astype(np.float64))
    _, reference = np.unique(cells, axis=0, return_inverse=True)
    reference = np.asarray(reference).reshape(-1)
    assert len(welded) == reference.max() + 1
    pairs = set(zip(label.tolist(), reference.tolist(), strict=True))
    assert len(pairs) == len(welded)  # a bijection between the two labellings
    np.testing.assert_array_equal(welded[label], cells.astype(np.float64))  # each cell's own point


@needs_numba
def test_object_facts_compiled_equal_the_numpy_reference():
    p, t, n = uv_sphere(24, 12)
    g, gt, gn = grid_plane(3, 2, (2.0, 1.0))
    rng = np.random.default_rng(2)
    cases = [
        (p, t, n),
        (p, t, None),
        (p.astype(np.float32).astype(np.float64), t, n),  # float32 coordinates: float32's tolerance
        (p * 1e3 + 5e3, t, n),
        (g, gt, gn),
        (g, gt, None),
        (g + rng.normal(size=g.shape) * 1e-3, gt, gn),  # no longer planar
        (np.r_[p, [[9.0, 9, 9]]], t, np.r_[n, [[0.0, 0, 1]]]),  # an unused vertex
        (p, np.r_[t, [[0, 0, 1]]], n),  # a degenerate triangle
    ]
    k = mf._kernels()
    e32, e64 = float(np.finfo(np.float32).eps), float(np.finfo(np.float64).eps)
    for pos, tri, nrm in cases:
        used, good, tol, planar, flat = mf._object_arrays_numpy(pos, tri, nrm)
        got = k["object_arrays"](
            pos, tri, np.zeros((0, 3)) if nrm is None else nrm, nrm is not None, e32, e64
        )
        np.testing.assert_array_equal(got[0], used)
        np.testing.assert_array_equal(got[1], good)
        assert got[2] == tol  # the same operations on the same numbers: equal bit for bit
        assert (bool(got[3]), bool(got[4])) == (planar, flat)
    assert mf._object_arrays_numpy(g, gt, gn)[3:] == (True, True)
    assert mf._object_arrays_numpy(p, t, n)[3:] == (False, False)


@needs_numba
def test_world_facts_follow_the_transform():
    p, t, n = uv_sphere(16, 8)
    transform = np.array([[2.0, 0.3, 0, 1], [0, 1.5, 0.2, -2], [0.1, 0, 0.5, 3], [0, 0, 0, 1]])
    facts = mf._mesh_facts(Mesh(p, t, n, transform=transform))
    world = p @ transform[:3, :3].T + transform[:3, 3]
    # 3-term sums in another order (BLAS) differ by a few ulps of the coordinates (≤ 10)
    np.testing.assert_allclose(facts.world, world, rtol=0, atol=1e-14)
    np.testing.assert_allclose(facts.lo, world.min(axis=0), rtol=0, atol=1e-14)
    np.testing.assert_allclose(facts.hi, world.max(axis=0), rtol=0, atol=1e-14)
    centre = (world.min(axis=0) + world.max(axis=0)) / 2
    assert facts.radius == pytest.approx(np.linalg.norm(world - centre, axis=1).max(), rel=1e-13)
    assert facts.closed and facts.convex
    mirrored = mf._mesh_facts(Mesh(p, t, n, transform=np.diag([1.0, -1.0, 1.0, 1.0])))
    assert mirrored.closed and not mirrored.convex  # a mirror winds the faces inwards


@needs_numba
def test_equal_arrays_are_analysed_once_and_different_ones_apart():
    mf._clear_caches()
    p, t, n = uv_sphere(40, 20)
    a = mf._object_facts(Mesh(p, t, n))
    assert mf._object_facts(Mesh(p, t, n, transform=np.diag([2.0, 1.0, 1.0, 1.0]))) is a  # same arrays
    assert mf._object_facts(Mesh(p.copy(), t.copy(), n.copy())) is a  # equal copies
    # a dent at a vertex the content fingerprint does not sample: the arrays differ, so do the facts
    step = max(1, p.size // 64)
    vertex = next(v for v in range(1, len(p) - 1) if all((3 * v + c) % step for c in range(3)))
    dented = p.copy()
    dented[vertex] *= 0.7
    assert mf._fingerprint(dented) == mf._fingerprint(p)
    b = mf._object_facts(Mesh(dented, t, n))
    assert b is not a and a.convex and not b.convex


def test_normal_angle_is_the_largest_angle_between_world_normals_of_an_edge():
    from blinn_phong.planning.calibration import max_normal_angle

    # closed form: a quad whose two far vertices' normals lean 30° and 50° (about x and y);
    # under a stretch by 2 along z the world normals (inverse transpose) lean atan(2·tan θ)
    points = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    a, b = np.radians(30.0), np.radians(50.0)
    normals = np.array([[0, 0, 1.0], [0, 0, 1.0], [0, np.sin(a), np.cos(a)], [np.sin(b), 0, np.cos(b)]])
    between = np.arccos(normals[2] @ normals[3])  # the diagonal 0–2 is 30°, the edge 2–3 is larger
    assert mf._normal_angle(Mesh(points, tris, normals)) == pytest.approx(between, abs=1e-12)
    squash = np.diag([1.0, 1.0, 2.0, 1.0])
    leaned = np.arctan(2.0 * np.tan(b))  # normal (sin b, 0, cos b) → (sin b, 0, cos b / 2)
    world = normals @ np.linalg.inv(squash[:3, :3])
    world /= np.linalg.norm(world, axis=1, keepdims=True)
    assert np.degrees(np.arccos(world[3, 2])) == pytest.approx(np.degrees(leaned), abs=1e-9)
    assert mf._normal_angle(Mesh(points, tris, normals, transform=squash)) == pytest.approx(
        np.arccos(np.clip(world[2] @ world[3], -1, 1)), abs=1e-12
    )
    # a perturbed sphere under a shear: the compiled pass against the numpy formula
    p, t, n = uv_sphere(30, 15)
    n = n + np.random.default_rng(3).normal(size=n.shape) * 0.05
    shear = np.array([[1.0, 0.4, 0, 0], [0, 1.2, 0, 0], [0.2, 0, 0.8, 0], [0, 0, 0, 1]])
    mesh = Mesh(p, t, n, transform=shear)
    # the transformed normals round differently in the last bits: ≤ 1e-7 rad apart (arccos
    # near 1 turns an ulp of the cosine into about 1.5e-8 rad)
    assert mf._normal_angle(mesh) == pytest.approx(max_normal_angle(mf._world_normals(mesh), t), abs=1e-7)


@needs_numba
@pytest.mark.parametrize("seed", range(4))
def test_hull_candidates_keep_every_hull_vertex(seed, monkeypatch):
    monkeypatch.setattr(mf, "_NUMPY_BELOW", 0)  # the compiled filter for these 3,000 points
    rng = np.random.default_rng(seed)
    flat = rng.normal(size=(3000, 2)) * rng.uniform(0.1, 10, size=2)
    if seed % 2:  # points on and inside a circle: many on the hull
        angle = rng.uniform(0, 2 * np.pi, size=3000)
        radius = np.where(rng.random(3000) < 0.3, 1.0, np.sqrt(rng.random(3000)))
        flat = np.stack([np.cos(angle), np.sin(angle)], axis=1) * radius[:, None] + 7.0
    kept = mf._hull_candidates(flat)
    assert len(kept) < len(flat)  # the filter does drop points
    full, reduced = ConvexHull(flat), ConvexHull(kept)
    expected = {tuple(p) for p in flat[full.vertices]}
    assert {tuple(p) for p in kept[reduced.vertices]} == expected  # Qhull: the same hull vertices
    assert reduced.volume == pytest.approx(full.volume, rel=1e-12)


def test_projected_width_of_a_box_is_its_thinnest_side():
    from tests.effects.geometry import box_triangles

    tris = box_triangles((0.0, 0.0, 0.0), (4.0, 1.0, 0.5)).reshape(-1, 3)
    p, t = hull_mesh(np.unique(tris, axis=0))
    facts = mf._mesh_facts(Mesh(p, t))
    # seen along z: a 4 × 1 rectangle, width 1; along x: 1 × 0.5, width 0.5
    assert mf._projected_width(facts, np.array([0.0, 0.0, -1.0])) == pytest.approx(1.0, rel=1e-12)
    assert mf._projected_width(facts, np.array([1.0, 0.0, 0.0])) == pytest.approx(0.5, rel=1e-12)
    # a dense sphere of radius 1 seen from anywhere: width 2 (the silhouette of its vertices)
    sp, st, sn = uv_sphere(317, 159)
    sphere = mf._mesh_facts(Mesh(sp, st, sn))
    assert mf._projected_width(sphere, np.array([0.3, 0.2, -1.0])) == pytest.approx(2.0, abs=1e-3)


def test_beyond_near_plane_matches_every_vertex_clip_test():
    import blinn_phong as bp

    p, t, n = uv_sphere(24, 12)
    camera = bp.Camera.perspective(50.0, 1.5, 0.5, 40.0, view=bp.look_at((0, 0, 5), (0, 0, 0)))
    clip_from_world = camera.projection @ camera.view
    rng = np.random.default_rng(4)
    answers = []
    for _ in range(60):
        move = np.eye(4)
        move[:3, 3] = rng.uniform([-3, -3, -4], [3, 3, 5.5])
        move[:3, :3] *= rng.uniform(0.2, 2.0)
        facts = mf._mesh_facts(Mesh(p, t, n, transform=move))
        clip = np.c_[facts.world, np.ones(len(facts.world))] @ clip_from_world.T
        expected = bool(np.all(clip[:, 3] > 0) and np.all(clip[:, 2] > -clip[:, 3]))  # every vertex
        assert mf._beyond_near_plane(facts, clip_from_world) == expected
        answers.append(expected)
    assert any(answers) and not all(answers)
