"""Per-mesh geometric facts the planner decides from: closedness, convexity, planarity, bounds.

:func:`_object_facts` analyses a mesh's object-space arrays once — which vertices are used,
which triangles have an area, whether the mesh is planar, closed and convex
(:func:`_convex_surface`), whether its normals are the face normals — and keeps the result by
the identity of the arrays and, failing that, by their content (several meshes sharing one
set of positions and triangles, or equal copies, are analysed once). :func:`_mesh_facts` adds
what depends on the transform: world positions, bounding box and sphere, the world plane.
The rest are conservative geometric tests on those facts (:func:`_may_shadow`, screen
rectangles, :func:`_projected_width`).

Every test runs compiled with numba when it imports (one linear pass over the triangles, the
edge adjacency built by a counting sort, welding by a hash table; nothing ``O(T log T)``), and
in numpy otherwise; both compute the same decisions (tests/effects/test_mesh_facts.py checks
them against each other and against :class:`scipy.spatial.ConvexHull`).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import math
import sys
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from blinn_phong.geometry.normals import vertex_normals
from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.model.scene import Mesh, Scene

__all__ = [
    "TriangleBalls",
    "coordinate_tolerance",
    "nearest_triangle_distance",
    "point_triangle_distances",
    "triangle_balls",
]

_EPS = 1e-9


@dataclass(frozen=True)
class _ObjectFacts:
    """Facts of a mesh's object-space geometry that every invertible affine transform keeps."""

    used: np.ndarray  # (V,) bool: vertex used by a triangle
    good: np.ndarray  # (T,) bool: triangle of non-zero area
    planar: bool  # every used vertex within the tolerance of the first good triangle's plane
    closed: bool
    convex: bool  # closed, every triangle on a supporting plane, counter-clockwise = outward
    flat_normals: bool


@dataclass(frozen=True)
class _MeshFacts:
    world: np.ndarray  # (U, 3) world positions of the used vertices
    mesh: Mesh
    n_tris: int
    centre: np.ndarray
    radius: float
    planar: bool
    plane: np.ndarray | None  # (a, b, c, d) unit normal when planar
    closed: bool
    convex: bool  # closed, convex and wound outwards in world space (see _convex_surface)
    flat_normals: bool
    lo: np.ndarray  # (3,) world bounding box: lowest corner
    hi: np.ndarray  # (3,) highest corner

    @property
    def tris(self) -> np.ndarray:
        """(T, 3, 3) world triangles (computed on demand)."""
        hom = np.c_[self.mesh.positions, np.ones(len(self.mesh.positions))]
        return (hom @ self.mesh.transform.T)[:, :3][self.mesh.triangles]

    @functools.cached_property
    def balls(self) -> TriangleBalls:
        """The world triangles with their bounding balls (computed once per facts: 104 bytes a
        triangle, held as long as the facts are cached)."""
        return triangle_balls(self.tris)


@dataclass(frozen=True, eq=False)
class TriangleBalls:
    """Triangles with the ball around each one's centroid through its farthest corner (read
    only: ``centre`` and ``radius`` are not recomputed if ``tris`` changes)."""

    tris: np.ndarray  # (T, 3, 3) corners
    centre: np.ndarray  # (T, 3) centroids
    radius: np.ndarray  # (T,) distance from the centroid to the farthest corner


def triangle_balls(triangles: np.ndarray) -> TriangleBalls:
    """:class:`TriangleBalls` of (T, 3, 3) ``triangles`` (as float64; a float64 array is kept,
    not copied)."""
    tri = np.asarray(triangles, dtype=np.float64)
    centre = tri.mean(axis=1)
    rel = tri - centre[:, None]
    return TriangleBalls(tri, centre, np.sqrt(np.einsum("tkc,tkc->tk", rel, rel).max(axis=1)))


def coordinate_tolerance(positions: np.ndarray) -> float:
    """Distance below which positions like ``positions`` are indistinguishable (their units).

    Coordinates that are all float32 numbers were computed in float32 at best, so their
    rounding error is float32's (ε = 2⁻²³); otherwise float64's (ε = 2⁻⁵²). A plane through
    three such points and a point's distance to it carry errors of a few ε·|p| (|p| the
    largest coordinate magnitude); the tolerance is ``64·ε·|p|`` — far above that rounding,
    far below any modelled feature (1.4·10⁻¹¹ for float64 coordinates of magnitude 10³,
    7.6·10⁻⁶ for float32 ones of magnitude 1).
    """
    p = np.asarray(positions, dtype=np.float64)
    if p.size == 0:
        return 0.0
    single = bool(np.array_equal(p.astype(np.float32).astype(np.float64), p))
    eps = float(np.finfo(np.float32 if single else np.float64).eps)
    return 64.0 * eps * max(float(np.abs(p).max()), 1e-300)


# --------------------------------------------------------------------------- numpy reference


def _directed_edges(triangles: np.ndarray, n_vertices: int) -> tuple[bool, np.ndarray]:
    """Whether every directed edge ``(i, j)`` occurs once with its twin ``(j, i)`` once; the sorted keys."""
    a = triangles.reshape(-1)
    b = triangles[:, [1, 2, 0]].reshape(-1)
    n = np.int64(max(n_vertices, 1))
    keys = np.sort(a * n + b)
    if len(keys) == 0 or np.any(a == b) or np.any(keys[1:] == keys[:-1]):
        return False, keys
    twins = b * n + a
    at = np.minimum(np.searchsorted(keys, twins), len(keys) - 1)
    return bool(np.all(keys[at] == twins)), keys


def _weld_cells(points: np.ndarray, tol: float) -> np.ndarray:
    """(V, 3) int64 cells of side ``4·tol``: vertices in one cell are welded into one."""
    cell = max(tol, 1e-300) * 4.0
    return np.round(points / cell).astype(np.int64)


def _convex_surface_numpy(points: np.ndarray, triangles: np.ndarray, tol: float) -> tuple[bool, bool]:
    """:func:`_convex_surface` in numpy (sorts of the edges and of the welded cells): the reference."""
    closed, keys = _directed_edges(triangles, len(points))
    if not closed:
        _, weld = np.unique(_weld_cells(points, tol), axis=0, return_inverse=True)
        weld = np.asarray(weld).reshape(-1)
        n_welded = int(weld.max()) + 1 if len(weld) else 0
        if n_welded == len(points):
            return False, False
        welded_points = np.zeros((n_welded, 3))
        welded_points[weld] = points
        triangles = weld[triangles]
        points = welded_points
        closed, keys = _directed_edges(triangles, len(points))
        if not closed:
            return False, False
    p0, p1, p2 = (points[triangles[:, k]] for k in range(3))
    fn = np.cross(p1 - p0, p2 - p0)
    length = np.sqrt(np.einsum("ij,ij->i", fn, fn))
    good = length > tol * np.sqrt(np.einsum("ij,ij->i", p1 - p0, p1 - p0))
    if not good.any():
        return True, False
    unit = fn[good] / length[good, None]
    base = p0[good]
    offset = np.einsum("ij,ij->i", unit, base)
    # (2) star-shaped around the centroid of the vertices
    used = np.zeros(len(points), dtype=bool)
    used[triangles.reshape(-1)] = True
    c = points[used].mean(axis=0)
    if not np.all(unit @ c - offset < -tol):
        return True, False
    # (3) winding number 1 around c
    a, b, d = p0 - c, p1 - c, p2 - c
    la, lb, ld = (np.sqrt(np.einsum("ij,ij->i", v, v)) for v in (a, b, d))
    num = np.einsum("ij,ij->i", a, np.cross(b, d))
    den = (
        la * lb * ld
        + np.einsum("ij,ij->i", a, b) * ld
        + np.einsum("ij,ij->i", a, d) * lb
        + np.einsum("ij,ij->i", b, d) * la
    )
    winding = float(np.sum(2.0 * np.arctan2(num, den))) / (4.0 * math.pi)
    if abs(winding - 1.0) > 0.25:
        return True, False
    # (1) vertex stars: neighbours of each corner on or below the triangle's plane
    n = np.int64(len(points))
    src, dst = keys // n, keys % n
    start = np.searchsorted(src, np.arange(len(points) + 1))
    corners = triangles[good].reshape(-1)
    deg = start[corners + 1] - start[corners]
    total = int(deg.sum())
    owner = np.repeat(np.arange(len(corners)) // 3, deg)
    first = np.repeat(start[corners] - (np.cumsum(deg) - deg), deg)
    neighbour = dst[first + np.arange(total)]
    height = np.einsum("ij,ij->i", points[neighbour], unit[owner]) - offset[owner]
    return True, bool(np.all(height <= tol))


def _object_arrays_numpy(
    pos: np.ndarray, tri: np.ndarray, normals: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, float, bool, bool]:
    """``(used, good, tol, planar, flat_normals)`` in numpy (see :func:`_object_facts`)."""
    used = np.zeros(len(pos), dtype=bool)
    used[tri.reshape(-1)] = True
    tol = coordinate_tolerance(pos[used]) if used.any() else 0.0
    if len(tri):
        p0 = pos[tri[:, 0]]
        fn = np.cross(pos[tri[:, 1]] - p0, pos[tri[:, 2]] - p0)
        fn_len = np.sqrt(np.einsum("ij,ij->i", fn, fn))
        good = fn_len > 0
    else:
        fn, fn_len, good = np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=bool)
    planar = False
    if good.any():
        first = int(np.argmax(good))
        n0 = fn[first] / fn_len[first]
        planar = bool(np.all(np.abs((pos[used] - pos[tri[first, 0]]) @ n0) <= tol))
    if normals is None or not good.any():
        flat_normals = normals is None  # decided from planarity by the caller
    else:
        nrm = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
        unit = fn[good] / fn_len[good, None]
        cos = np.einsum("tkc,tc->tk", nrm[tri[good]], unit)
        flat_normals = bool(np.all(cos >= 1 - 1e-9))
    return used, good, tol, planar, flat_normals


# --------------------------------------------------------------------------- compiled


@functools.lru_cache(maxsize=1)
def _kernels() -> dict[str, object] | None:
    """The compiled twins of the numpy reference (:mod:`blinn_phong.geometry._mesh_kernels`), or None
    without numba. Same arithmetic as the numpy path, operation for operation; serial (each
    pass takes a few milliseconds, less than numba threads' start and join on a busy machine).
    """
    try:
        from blinn_phong.geometry import _mesh_kernels as m
    except Exception:
        return None
    names = (
        "object_arrays",
        "rows",
        "paired",
        "weld",
        "convex",
        "world_bounds",
        "normal_angle",
        "outside_polygon",
    )
    return {name: getattr(m, name) for name in names}


#: Meshes from this many triangles use the compiled passes even when numba is not loaded yet
#: (its start costs seconds once per process; below this the numpy reference takes
#: milliseconds). Once numba is loaded — a render imports it — every mesh uses them.
_COMPILED_FROM = 20_000


#: True while a frame renders with the numpy engine (:func:`reference_only`): the facts use the
#: numpy reference too, so that such a frame compiles nothing (a frame rendered while its kernels
#: compile elsewhere must not compile them itself).
_REFERENCE_ONLY: contextvars.ContextVar[bool] = contextvars.ContextVar("reference_only", default=False)


@contextlib.contextmanager
def reference_only() -> Iterator[None]:
    """Within the block, every fact is computed by the numpy reference (no kernel compiles)."""
    token = _REFERENCE_ONLY.set(True)
    try:
        yield
    finally:
        _REFERENCE_ONLY.reset(token)


#: Meshes below this many triangles use the numpy reference even when numba is loaded: it takes
#: milliseconds once per mesh (measured on the 2-core VM: 0.8 ms at 224 triangles, 5 ms at
#: 2,208, 30 ms at 9,024), while the compiled passes cost about 5 s of compilation in the first
#: process on a machine (``docs/compile.md``): an everyday scene of small meshes compiles none.
_NUMPY_BELOW = 5_000


def _compiled(n: int) -> dict[str, object] | None:
    """The compiled passes for a mesh of ``n`` triangles (or points), or None for the numpy
    reference: both decide the same (tested); the choice is only about time."""
    if _REFERENCE_ONLY.get() or n < _NUMPY_BELOW or (n < _COMPILED_FROM and "numba" not in sys.modules):
        return None
    return _kernels()


def _convex_surface(
    points: np.ndarray, triangles: np.ndarray, tol: float, used: np.ndarray | None = None
) -> tuple[bool, bool]:
    """``(closed, convex)`` of an indexed triangle mesh by local tests, in linear time.

    ``closed``: every directed edge ``(i, j)`` occurs once and its twin ``(j, i)`` once — a
    closed, consistently wound surface. When the indexed mesh is not, vertices within ``tol``
    of each other are welded first (a cube with 4 vertices per face is closed).

    ``convex``: closed, and every triangle lies on a supporting plane of the vertex set with
    its counter-clockwise normal pointing away from it (the surface is the boundary of the
    convex hull, wound outwards). Tested by three facts, each within ``tol``:

    1. *vertex stars*: for every triangle ``t`` and each corner ``v`` of ``t``, every
       neighbour ``w`` of ``v`` (sharing an edge with it) lies on or below ``t``'s plane;
    2. *star-shaped*: the centroid ``c`` of the vertices lies strictly below (by more than
       ``tol``) every triangle's plane;
    3. *winding number 1*: the solid angles of the triangles seen from ``c`` (Van Oosterom &
       Strackee, IEEE Trans. Biomed. Eng. 30, 1983) add up to 4π.

    Why they suffice. By (2) the central projection from ``c`` onto the unit sphere maps each
    triangle one-to-one, preserving orientation; the surface being closed, the projection has
    a degree, the winding number of (3), so every direction off the projected edges has
    exactly one preimage: the surface is embedded, a radial graph around ``c``, bounding a
    closed, connected solid ``K``. By (1), at each vertex ``v`` the plane of every triangle at
    ``v`` supports ``Q = conv({v} ∪ neighbours(v))``, so those triangles lie on ``∂Q``; since
    they surround ``v`` on the embedded closed surface, ``K`` coincides with ``Q`` near ``v``,
    and so near every point of the triangles and edges at ``v``. ``K`` is therefore locally
    convex at every point and, closed and connected, convex (Tietze–Nakajima theorem;
    Valentine, *Convex Sets*, 1964, thm. 4.4): every triangle lies on a supporting plane of
    ``K = conv(vertices)``. Conversely a convex closed mesh passes (1)–(3) up to rounding,
    which ``tol`` covers (:func:`coordinate_tolerance`).

    The proof reads only the three facts, not how they are computed: the compiled path and the
    numpy reference (:func:`_convex_surface_numpy`) compute the same sets — the same directed
    edges (here rows of out-neighbours per vertex by a counting sort instead of one sort of
    edge keys; in a closed mesh a vertex's out-neighbours are all its neighbours), the same
    welded cells (a hash table instead of a sort; welding needs only which vertices share a
    cell, not the cells' order), the same per-triangle planes, heights and solid angles.

    The compiled pass skips, in (1), the neighbours that are corners of ``t`` itself: they
    lie on ``t``'s plane, so (1) holds for them whatever the rounding.

    Cost: linear. Building the rows is one counting pass over the 3T directed edges; each row
    is checked for a repeated neighbour, and the twin of each edge ``(v, w)`` with ``v < w`` is
    found by scanning ``w``'s row (about 6 entries; rows longer than 32 are sorted and
    bisected), the mesh being closed when those pairs cover all 3T edges; then one pass over
    the triangles computing each plane once, its dozen neighbour heights and its solid angle,
    stopping at the first failed test. No hull is built.
    ``used`` (the vertices of the triangles, optional) saves a pass.
    """
    k = _compiled(len(triangles))
    if k is None:
        return _convex_surface_numpy(points, triangles, tol)
    points = np.ascontiguousarray(points, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    closed, start, dst = _closed_rows(k, triangles, len(points))
    if not closed:
        label, welded = k["weld"](_weld_cells(points, tol), points)
        if len(welded) == len(points):
            return False, False
        points, triangles, used = welded, label[triangles], None
        closed, start, dst = _closed_rows(k, triangles, len(points))
        if not closed:
            return False, False
    if used is None:
        used = np.zeros(len(points), dtype=bool)
        used[triangles.reshape(-1)] = True
    return True, bool(k["convex"](points, triangles, used, float(tol), start, dst))


def _closed_rows(k: dict, triangles: np.ndarray, n_vertices: int) -> tuple[bool, np.ndarray, np.ndarray]:
    """Whether the indexed mesh is closed (every directed edge once, its twin once), and the
    sorted rows of out-neighbours per vertex (``start``, ``dst``)."""
    simple, start, dst = k["rows"](triangles, n_vertices)
    if not simple:
        return False, start, dst
    return bool(k["paired"](start, dst)), start, dst


# --------------------------------------------------------------------------- cached facts

#: Object facts by the identity of (positions, triangles, normals): (the mesh, its facts).
_OBJECT_FACTS: dict[tuple[int, int, int], tuple[Mesh, _ObjectFacts]] = {}
#: Object facts by a fingerprint of the arrays' content: (the arrays, their facts), checked equal.
_CONTENT_FACTS: dict[tuple, tuple[tuple[np.ndarray, np.ndarray, np.ndarray | None], _ObjectFacts]] = {}
_WORLD_FACTS: dict[tuple[int, int, int, bytes], _MeshFacts] = {}
_CACHE_SIZE = 64


def _clear_caches() -> None:
    """Forget every cached fact (benchmarks time first-time planning with it)."""
    _OBJECT_FACTS.clear()
    _CONTENT_FACTS.clear()
    _WORLD_FACTS.clear()


def _fingerprint(a: np.ndarray | None) -> tuple:
    """Shape, dtype and 64 sampled elements of ``a``: equal arrays have equal fingerprints."""
    if a is None:
        return (None,)
    flat = a.reshape(-1)
    step = max(1, flat.size // 64)
    return (a.shape, a.dtype.str, flat[::step].tobytes())


def _put(cache: dict, key: object, value: object) -> None:
    if len(cache) >= _CACHE_SIZE:
        cache.pop(next(iter(cache)))
    cache[key] = value


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is b
    return a is b or (a.shape == b.shape and a.dtype == b.dtype and bool(np.array_equal(a, b)))


def _object_facts(mesh: Mesh) -> _ObjectFacts:
    """Object-space facts of ``mesh``, cached by the identity of its arrays and by their content
    (Mesh arrays are not to be changed in place; equal arrays have equal facts, so meshes that
    share geometry — or hold equal copies of it — are analysed once)."""
    key = (id(mesh.positions), id(mesh.triangles), id(mesh.normals))
    hit = _OBJECT_FACTS.get(key)
    if (
        hit is not None
        and hit[0].positions is mesh.positions
        and hit[0].triangles is mesh.triangles
        and hit[0].normals is mesh.normals
    ):
        return hit[1]
    arrays = (mesh.positions, mesh.triangles, mesh.normals)
    content = tuple(_fingerprint(a) for a in arrays)
    found = _CONTENT_FACTS.get(content)
    if found is not None and all(_same(a, b) for a, b in zip(found[0], arrays, strict=True)):
        _put(_OBJECT_FACTS, key, (mesh, found[1]))
        return found[1]
    facts = _analyse(*arrays)
    _put(_OBJECT_FACTS, key, (mesh, facts))
    _put(_CONTENT_FACTS, content, (arrays, facts))
    return facts


def _analyse(pos: np.ndarray, tri: np.ndarray, normals: np.ndarray | None) -> _ObjectFacts:
    """The :class:`_ObjectFacts` of one mesh's arrays, compiled when numba imports."""
    k = _compiled(len(tri))
    if k is None:
        used, good, tol, planar, flat_normals = _object_arrays_numpy(pos, tri, normals)
    else:
        pos = np.ascontiguousarray(pos, dtype=np.float64)
        tri = np.ascontiguousarray(tri, dtype=np.int64)
        nrm = np.zeros((0, 3)) if normals is None else np.ascontiguousarray(normals, dtype=np.float64)
        eps32, eps64 = float(np.finfo(np.float32).eps), float(np.finfo(np.float64).eps)
        used, good, tol, planar, flat_normals = k["object_arrays"](
            pos, tri, nrm, normals is not None, eps32, eps64
        )
        tol, planar, flat_normals = float(tol), bool(planar), bool(flat_normals)
    closed, convex = _convex_surface(pos, tri, tol, used) if len(tri) else (False, False)
    return _ObjectFacts(used, good, planar, closed, convex, flat_normals)


def _mesh_facts(mesh: Mesh) -> _MeshFacts:
    """World-space facts of ``mesh``, cached by its arrays' identity and its transform."""
    obj = _object_facts(mesh)
    key = (id(mesh.positions), id(mesh.triangles), id(mesh.normals), mesh.transform.tobytes())
    hit = _WORLD_FACTS.get(key)
    if hit is not None and _OBJECT_FACTS.get(key[:3], (None, None))[1] is obj:
        if hit.mesh is mesh:
            return hit
        moved = replace(hit, mesh=mesh)
        if "balls" in hit.__dict__:  # the same world triangles: their cached balls too
            moved.__dict__["balls"] = hit.__dict__["balls"]
        return moved
    linear = mesh.transform[:3, :3]
    k = _compiled(len(mesh.triangles))
    if k is None:
        world = mesh.positions[obj.used] @ linear.T + mesh.transform[:3, 3]
        if len(world):
            lo, hi = world.min(axis=0), world.max(axis=0)
            centre = (lo + hi) / 2
            radius = float(np.sqrt(np.max(np.einsum("ij,ij->i", world - centre, world - centre))))
    else:
        world, lo, hi, radius = k["world_bounds"](
            np.ascontiguousarray(mesh.positions, dtype=np.float64),
            obj.used,
            np.ascontiguousarray(mesh.transform[:3], dtype=np.float64),
        )
        centre, radius = (lo + hi) / 2, float(radius)
    if len(world) == 0:
        return _MeshFacts(
            world, mesh, 0, np.zeros(3), 0.0, False, None, False, False, False, np.zeros(3), np.zeros(3)
        )
    plane = None
    if obj.planar:  # an affine map keeps a plane: its world equation from the first good face
        first = int(np.argmax(obj.good))
        corner = (np.c_[mesh.positions[mesh.triangles[first]], np.ones(3)] @ mesh.transform.T)[:, :3]
        n0 = np.cross(corner[1] - corner[0], corner[2] - corner[0])
        n0 = n0 / np.linalg.norm(n0)
        plane = np.r_[n0, -float(n0 @ corner[0])]
    # an invertible affine map keeps convexity; a mirror (det < 0) turns the winding inwards
    convex = obj.convex and float(np.linalg.det(linear)) > 0
    flat_normals = obj.planar if mesh.normals is None else obj.flat_normals
    facts = _MeshFacts(
        world,
        mesh,
        len(mesh.triangles),
        centre,
        radius,
        obj.planar,
        plane,
        obj.closed,
        convex,
        flat_normals,
        lo,
        hi,
    )
    _put(_WORLD_FACTS, key, facts)
    return facts


# --------------------------------------------------------------------------- geometric tests


def _screen_rect_and_depth(facts: _MeshFacts, scene: Scene) -> tuple[np.ndarray, tuple[float, float]]:
    """NDC rectangle (x0, y0, x1, y1) and eye distance interval (−z) of a mesh."""
    hom = np.c_[facts.world, np.ones(len(facts.world))]
    eye = hom @ scene.camera.view.T
    clip = eye @ scene.camera.projection.T
    depth = (-float(eye[:, 2].max()), -float(eye[:, 2].min()))
    if np.any(clip[:, 3] <= 0):
        return np.array([-np.inf, -np.inf, np.inf, np.inf]), depth
    ndc = clip[:, :2] / clip[:, 3:4]
    return np.r_[ndc.min(axis=0), ndc.max(axis=0)], depth


def _rects_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3])


def _beyond_near_plane(facts: _MeshFacts, clip_from_world: np.ndarray) -> bool:
    """Whether every vertex of the mesh has clip ``w > 0`` and ``z > −w`` (wholly beyond the
    near plane). Both are linear in the world position, so when they hold at the 8 corners of
    the bounding box they hold at every vertex inside it (the vertices are then not read);
    otherwise the vertices are tested."""
    w_row, near_row = clip_from_world[3], clip_from_world[2] + clip_from_world[3]
    corners = np.array(
        [
            [x, y, z, 1.0]
            for x in (facts.lo[0], facts.hi[0])
            for y in (facts.lo[1], facts.hi[1])
            for z in (facts.lo[2], facts.hi[2])
        ]
    )
    if np.all(corners @ w_row > 0) and np.all(corners @ near_row > 0):
        return True
    hom = np.c_[facts.world, np.ones(len(facts.world))]
    clip = hom @ clip_from_world.T
    return bool(np.all(clip[:, 3] > 0) and np.all(clip[:, 2] > -clip[:, 3]))


def _box_min(plane: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """A lower bound of ``n·p + d`` over the box ``[lo, hi]`` (its lowest corner)."""
    n = plane[:3]
    return float(np.sum(np.where(n >= 0, lo, hi) * n) + plane[3])


def _may_shadow(
    caster: _MeshFacts, receiver: _MeshFacts, light: DirectionalLight | PointLight | SpotLight
) -> bool:
    """Conservative: can ``caster`` lie between ``light`` and any point of ``receiver``?"""
    if caster.planar and caster.plane is not None:
        # a flat caster shades only what lies on its far side from the light
        oriented, _ = _light_side_distance(caster.plane, light)
        limit = -_EPS * max(receiver.radius, 1.0)
        # the receiver's bounding box bounds its vertices' heights from below: when its lowest
        # corner already clears the limit, every vertex does (the same answer, without them)
        if _box_min(oriented, receiver.lo, receiver.hi) >= limit:
            return False
        if float(np.min(receiver.world @ oriented[:3]) + oriented[3]) >= limit:
            return False
    r = caster.radius + receiver.radius
    if not light.positional:
        d = np.asarray(light.direction)  # the direction light travels
        w = receiver.centre - caster.centre
        along = float(w @ d)
        if along < -r:
            return False  # receiver entirely on the light's side of the caster
        perp = float(np.linalg.norm(w - max(along, 0.0) * d))
        return perp < r
    pos = np.asarray(light.position)
    to_c = caster.centre - pos
    to_r = receiver.centre - pos
    dc, dr = float(np.linalg.norm(to_c)), float(np.linalg.norm(to_r))
    if dc <= caster.radius or dr <= receiver.radius:
        return True  # the light is inside a bounding sphere
    if dr + receiver.radius < dc - caster.radius:
        return False  # receiver entirely nearer the light than the caster
    angle = math.acos(float(np.clip(to_c @ to_r / (dc * dr), -1, 1)))
    return angle < math.asin(min(caster.radius / dc, 1.0)) + math.asin(min(receiver.radius / dr, 1.0))


def _light_side_distance(
    plane: np.ndarray, light: DirectionalLight | PointLight | SpotLight
) -> tuple[np.ndarray, float]:
    """Plane oriented towards the light, and the light's signed distance (inf if directional)."""
    n, d = plane[:3], plane[3]
    if not light.positional:
        towards = -np.asarray(light.direction)
        if float(n @ towards) < 0:
            n, d = -n, -d
        return np.r_[n, d], math.inf
    lp = np.asarray(light.position)
    h = float(n @ lp + d)
    if h < 0:
        n, d, h = -n, -d, -h
    return np.r_[n, d], h


def _hull_candidates(flat: np.ndarray) -> np.ndarray:
    """The points of ``flat`` (N, 2) that may be vertices of its convex hull (the Akl–Toussaint
    heuristic, Inf. Process. Lett. 7, 1978, with 16 directions): the extreme points along
    directions 22.5° apart, taken by angle, form a convex polygon inside the hull,
    counter-clockwise; a point strictly inside it — by more than ``10⁻⁹·|p|²`` in the edge
    functions, far above their rounding — is inside the hull and no vertex of it, so dropping
    it leaves the hull as it is. Compiled when numba imports; every point otherwise."""
    k = _compiled(len(flat))
    if k is None or len(flat) < 256:
        return flat
    angles = np.arange(16) * (np.pi / 8)
    directions = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    margin = 1e-9 * float(np.abs(flat).max()) ** 2
    return flat[k["outside_polygon"](np.ascontiguousarray(flat), directions, margin)]


def _projected_width(f: _MeshFacts, direction: np.ndarray) -> float:
    """Smallest extent (world units) of a mesh seen along ``direction``, the light's view.

    The vertices are projected on the plane across ``direction``; the minimum width of a
    planar point set is attained across one edge of its convex hull (rotating calipers,
    Toussaint 1983), so it is the smallest, over the hull's edges, of the extent of the hull
    along the edge's normal. 0 for a pane seen edge-on. Qhull sees only the points that may be
    hull vertices (:func:`_hull_candidates`): the same hull from a fraction of the points.
    """
    from scipy.spatial import ConvexHull, QhullError

    d = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    flat = np.c_[f.world @ u, f.world @ v]
    flat = _hull_candidates(flat - flat.mean(axis=0))
    try:
        hull = ConvexHull(flat)
    except (QhullError, ValueError):  # collinear or too few points: no area seen from the light
        return 0.0
    corners = flat[hull.vertices]
    along = corners @ hull.equations[:, :2].T  # (H, E): unit edge normals
    return float(np.min(along.max(axis=0) - along.min(axis=0)))


def _world_normals(mesh: Mesh) -> np.ndarray:
    """Vertex normals in world space (the inverse transpose of the linear part), as the renderer uses them."""
    normals = mesh.normals if mesh.normals is not None else vertex_normals(mesh.positions, mesh.triangles)
    return np.asarray(normals, dtype=np.float64) @ np.linalg.inv(mesh.transform[:3, :3])


def _normal_angle(mesh: Mesh) -> float:
    """Largest angle (radians) between the world-space vertex normals at the two ends of any
    triangle edge: :func:`blinn_phong.geometry.normals.max_normal_angle` of :func:`_world_normals`,
    in one compiled pass when numba imports (the same value up to the rounding of the normals'
    transform, a few ulps: about 10⁻⁸ rad where the normals are parallel)."""
    k = _compiled(len(mesh.triangles))
    if k is None or mesh.normals is None or len(mesh.triangles) == 0:
        from blinn_phong.geometry.normals import max_normal_angle

        return max_normal_angle(_world_normals(mesh), mesh.triangles)
    inverse = np.linalg.inv(mesh.transform[:3, :3])
    normals = np.ascontiguousarray(mesh.normals, dtype=np.float64)
    return float(k["normal_angle"](normals, np.ascontiguousarray(mesh.triangles, dtype=np.int64), inverse))


def point_triangle_distances(triangles: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(T,) Euclidean distance from ``point`` to each triangle (its closest point, edges included).

    Args:
        triangles: (T, 3, 3) world-space corners.
        point: (3,) world-space point.

    The closest point is the projection onto the triangle's plane when that falls inside the
    triangle (all three edge tests agree in sign), else the nearest point of its three edges
    (segment projection clamped to [0, 1]). Degenerate (zero-area) triangles give their edge
    distance. Float64 throughout.
    """
    tri = np.asarray(triangles, dtype=np.float64)
    p = np.asarray(point, dtype=np.float64)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    best = np.full(len(tri), np.inf)
    for s, e in ((a, b), (b, c), (c, a)):
        d = e - s
        length2 = np.einsum("ij,ij->i", d, d)
        t = np.einsum("ij,ij->i", p - s, d) / np.where(length2 > 0, length2, 1.0)
        closest = s + np.clip(t, 0.0, 1.0)[:, None] * d
        best = np.minimum(best, np.linalg.norm(p - closest, axis=1))
    n = np.cross(b - a, c - a)
    area2 = np.linalg.norm(n, axis=1)
    good = area2 > 0
    unit = n[good] / area2[good, None]
    height = np.einsum("ij,ij->i", p - a[good], unit)
    foot = p - height[:, None] * unit
    inside = np.ones(int(good.sum()), bool)
    for s, e in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(e[good] - s[good], foot - s[good]), unit) >= 0
    plane_distance = np.where(inside, np.abs(height), np.inf)
    best[good] = np.minimum(best[good], plane_distance)
    return best


def nearest_triangle_distance(triangles: np.ndarray | TriangleBalls, point: np.ndarray) -> float:
    """The smallest of :func:`point_triangle_distances`, exactly, without computing most of them.

    Args:
        triangles: (T, 3, 3) corners (any one space, e.g. world or eye space), or their
            :class:`TriangleBalls` (e.g. a mesh's cached :attr:`_MeshFacts.balls`).
        point: (3,) a point of the same space.

    Returns ``inf`` for no triangles. Every point of a triangle lies in the ball around its
    centroid ``m`` through its farthest corner (radius ``ρ``), so its distance is at least
    ``|p − m| − ρ``; the nearest corner of all is a point of the triangles, so the answer is at
    most that corner's distance ``u``. Only triangles with ``|p − m| − ρ ≤ u`` can hold the
    nearest point, and only their exact distances are computed: the same minimum, for a few
    dozen of a closed mesh's thousands. The test keeps a margin of 10⁻⁹ of the distances and
    sizes involved plus 64 float64 rounding units of the coordinates' magnitude, far above the
    rounding of ``|p − m| − ρ``. Non-finite coordinates take every triangle (the result is then
    :func:`point_triangle_distances`'s, NaN included).
    """
    balls = triangles if isinstance(triangles, TriangleBalls) else triangle_balls(triangles)
    p = np.asarray(point, dtype=np.float64)
    if len(balls.tris) == 0:
        return math.inf
    to_centre = balls.centre - p
    lower = np.sqrt(np.einsum("tc,tc->t", to_centre, to_centre)) - balls.radius
    if not np.isfinite(lower).all():
        return float(point_triangle_distances(balls.tris, p).min())
    nearest = int(np.argmin(lower))  # a triangle whose corners are among the nearest
    corners = balls.tris[lower <= lower[nearest] + 2.0 * balls.radius[nearest]] - p
    upper = float(np.sqrt(np.einsum("tkc,tkc->tk", corners, corners).min()))
    magnitude = max(float(np.abs(p).max()), float(np.abs(balls.centre).max()))
    margin = 1e-9 * (upper + float(balls.radius.max())) + 64.0 * float(np.finfo(np.float64).eps) * magnitude
    keep = lower <= upper + max(margin, 1e-300)
    return float(point_triangle_distances(balls.tris[keep], p).min())
