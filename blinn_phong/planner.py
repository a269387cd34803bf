"""The planner: per concern, the fastest method that is exact or predicted within a tolerance.

:func:`plan` inspects a :class:`~blinn_phong.scene.Scene` — geometry, materials, lights,
camera — and returns a :class:`Plan`: one :class:`Choice` (method, parameters, a sentence
saying why, and for approximations the predicted error and relative cost) for
transparency, one per light for shadows and one per mesh for the shading frequency. It
renders nothing. Exact methods are picked from conservative geometric facts; with a
tolerance ``T > 0`` in **8-bit steps** (1/255 of the unit range) an approximate method is
picked where a bound (or the measured error model of :mod:`blinn_phong.calibration`)
keeps it within ``T`` and its measured cost model predicts it faster than the exact method
for the frame (``width``, ``height``, ``samples``). ``T = 0`` means exact methods only.

``T`` means one thing for every concern (docs/speed_accuracy.md, "What the tolerance
promises"): **no channel of any pixel differs by more than T steps** from the image every
exact method gives (A-buffer, ray-traced shadows, per-pixel shading of the exact surface).

Transparency (methods of :mod:`blinn_phong.oit`):

* ``zbuffer`` — no material has opacity < 1.
* ``draw_last`` — one transparent mesh, planar or convex: drawn after the opaque ones,
  back faces first, then front faces; along any view ray a convex mesh's back face lies
  behind its front face, and a planar mesh never overlaps itself.
* ``sort_objects`` — several transparent meshes, each planar or convex, and every pair
  whose screen rectangles overlap is separated in eye depth: drawing them back to front
  (each as in ``draw_last``) follows the per-pixel order everywhere.
* ``depth_peeling`` — with a tolerance: the fewest layers ``k`` whose predicted max error
  ``255·c·B·(1 − α_min)^k`` is within it (what lies behind ``k`` layers is scaled by their
  transmittance, at most ``(1 − α_min)^k``; ``B`` bounds the straight radiance behind them
  with every factor of the lighting equation — emission, ambient, light colours, and the
  attenuation ``1/(k_c + k_l·d + k_q·d²)`` at the smallest distance from the light to a
  mesh, above 1 when ``k_c < 1`` — see :func:`_max_radiance`; at least 1 because alpha
  counts too; divided by ``α_min`` for the absorption model whose fragments are not
  premultiplied by their opacity; ``c`` measured), if its predicted cost ``t₀ + t₁·k`` is
  below the A-buffer's.
* ``a_buffer`` — otherwise (surfaces may interpenetrate or overlap in depth): exact.

Shadows, per light (:mod:`blinn_phong.shadows`, :mod:`blinn_phong.raytrace`):

* ``none`` — ambient lights; or no mesh can shade another from this light: every caster's
  shadow volume (the cylinder or cone its bounding sphere sweeps away from the light)
  misses every other mesh's bounding sphere, and no mesh can shade itself: planar, or
  closed and convex (:func:`_convex_surface`, a tolerance from the coordinates' precision)
  and never lit from inside — one-sided lighting, or two-sided with the mesh opaque and
  wholly beyond the near plane (:func:`_self_shadow_free`). An open box under two-sided
  lighting shades its own floor.
* ``planar`` — every receiver that can be shadowed is a planar mesh on one common plane and
  every caster lies between that plane and the light: Blinn's projected shadows are exact.
* ``shadow_map`` — with a tolerance, directional lights (the calibrated case), only when
  ``255·w ≤ T``: ``w`` is the largest change a pixel sees between lit and shadowed (the
  light's diffuse and specular colours times the materials', times the attenuation bound),
  which a misplaced hard edge costs in full. The resolution is the smallest power of two
  whose texel ``D/R`` (``D`` the map's span) is at most half the thinnest caster seen from
  the light (the smallest extent of its projection across the light direction,
  :func:`_projected_width`), if its predicted cost for the frame's receiver samples is below
  ray tracing's.
* ``shadow_volume`` — exact hard shadows by stencil counting (:mod:`blinn_phong.shadow_volume`):
  where Embree cannot be imported (for every hard shadow, ``planar`` included, which tests
  points with it), or where the fitted cost model
  (:func:`blinn_phong.calibration.shadow_volume_cost`, the scene's triangles and the frame's
  receiver samples) predicts them faster than Embree ray tracing and ``255·w ≤ T``: the two
  exact methods may classify a sample whose shadow ray grazes a silhouette differently, which
  costs a pixel the light's whole contribution ``w`` against the ray tracer's image (see
  :func:`_exact_shadow`).
* ``ray_traced`` — otherwise: exact hard shadows.

Shading frequency, per mesh (:mod:`blinn_phong.render`):

* ``flat`` — every triangle's vertex normals equal its face normal (planar faces), all
  lights are directional or ambient and the viewer is at infinity
  (``LightModel(local_viewer=False)``, what an orthographic camera should use): L, H and N
  are constant over each face, so the lighting is.
* ``flat`` or ``gouraud`` — with a tolerance, shininess within the calibrated range: the
  cheaper one whose predicted max error ``margin·a·θ^b`` (``θ`` the largest angle between
  adjacent vertex normals) is within it, if it is measured faster than Phong.
* ``phong`` — otherwise (per-pixel evaluation, the reference).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import calibration
from .normals import vertex_normals
from .scene import AmbientLight, DirectionalLight, Material, Mesh, PointLight, Scene, SpotLight

__all__ = [
    "DEFAULT_FRAME",
    "Choice",
    "MapGeometry",
    "Plan",
    "coloured_shadow_reason",
    "coordinate_tolerance",
    "embree_available",
    "plan",
    "shadow_map_geometry",
]

_EPS = 1e-9


@dataclass(frozen=True)
class Choice:
    """One decision: ``method``, its ``params``, the ``reason`` and, for approximations, predictions.

    ``params`` are keyword arguments of the function that carries the method out:
    ``layers`` for :func:`blinn_phong.oit.resolve_transparency`, ``plane`` or ``resolution``
    for :func:`blinn_phong.shadows.light_visibility`. ``predicted_steps`` is the error the
    calibrated model predicts (8-bit steps, in the concern's metric, see :func:`plan`; 0 for
    the exact method of a concern) and ``relative_cost`` the predicted time relative to that
    exact method (A-buffer, ray tracing, Phong); both None where no model applies.
    """

    method: str
    reason: str
    params: dict[str, object] = field(default_factory=dict)
    predicted_steps: float | None = None
    relative_cost: float | None = None

    def __str__(self) -> str:
        extra = ", ".join(f"{k}={v}" for k, v in self.params.items())
        return f"{self.method}{f' ({extra})' if extra else ''}: {self.reason}"


@dataclass(frozen=True)
class Plan:
    """The planner's decisions for one scene.

    Attributes:
        transparency: how transparent fragments are resolved.
        shadows: one choice per entry of ``scene.lights`` (same order).
        shading: one choice per entry of ``scene.meshes`` (same order).
        tolerance: the tolerance the plan was made for, in 8-bit steps (0: exact only).
    """

    transparency: Choice
    shadows: tuple[Choice, ...]
    shading: tuple[Choice, ...]
    tolerance: float

    def reasons(self) -> list[str]:
        """Every decision as one human-readable line."""
        lines = [f"transparency: {self.transparency}"]
        lines += [f"shadows, light {i}: {c}" for i, c in enumerate(self.shadows)]
        lines += [f"shading, mesh {i}: {c}" for i, c in enumerate(self.shading)]
        return lines

    def __str__(self) -> str:
        return "\n".join(self.reasons())


# --------------------------------------------------------------------------- geometry facts


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

    @property
    def tris(self) -> np.ndarray:
        """(T, 3, 3) world triangles (computed on demand)."""
        hom = np.c_[self.mesh.positions, np.ones(len(self.mesh.positions))]
        return (hom @ self.mesh.transform.T)[:, :3][self.mesh.triangles]


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


def _convex_surface(points: np.ndarray, triangles: np.ndarray, tol: float) -> tuple[bool, bool]:
    """``(closed, convex)`` of an indexed triangle mesh by local tests (one sort of the edges).

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

    Cost: sorting the 3T directed edges, then about 18·T point–plane distances (a vertex has
    about 6 neighbours); no hull is built.
    """
    closed, keys = _directed_edges(triangles, len(points))
    if not closed:
        cell = max(tol, 1e-300) * 4.0
        _, weld = np.unique(np.round(points / cell).astype(np.int64), axis=0, return_inverse=True)
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
    if len(corners) >= _COMPILED_STARS and _star_kernel() is not None:
        highest = _star_kernel()(points, corners, unit, offset, start, dst, tol)  # type: ignore[operator]
        return True, bool(highest <= tol)
    deg = start[corners + 1] - start[corners]
    total = int(deg.sum())
    owner = np.repeat(np.arange(len(corners)) // 3, deg)
    first = np.repeat(start[corners] - (np.cumsum(deg) - deg), deg)
    neighbour = dst[first + np.arange(total)]
    height = np.einsum("ij,ij->i", points[neighbour], unit[owner]) - offset[owner]
    return True, bool(np.all(height <= tol))


#: Corners from which the vertex-star test runs compiled (numba), when numba imports.
_COMPILED_STARS = 60_000


@functools.lru_cache(maxsize=1)
def _star_kernel() -> object | None:
    """The vertex-star test of :func:`_convex_surface` compiled with numba (None without numba):
    the largest height of a neighbour of a corner above its triangle's plane, stopping at the
    first one above ``tol``. Same arithmetic as the numpy path, one pass, no gathered copies."""
    try:
        import numba
    except Exception:
        return None

    @numba.njit(cache=True)
    def highest(points, corners, unit, offset, start, dst, tol):  # pragma: no cover - compiled
        worst = -np.inf
        for c in range(corners.shape[0]):
            g = c // 3
            v = corners[c]
            for e in range(start[v], start[v + 1]):
                w = dst[e]
                h = (
                    points[w, 0] * unit[g, 0] + points[w, 1] * unit[g, 1] + points[w, 2] * unit[g, 2]
                ) - offset[g]
                if h > worst:
                    worst = h
                    if worst > tol:
                        return worst
        return worst

    return highest


_OBJECT_FACTS: dict[tuple[int, int, int], tuple[Mesh, _ObjectFacts]] = {}


def _object_facts(mesh: Mesh) -> _ObjectFacts:
    """Object-space facts of ``mesh``, cached by the identity of its arrays (Mesh arrays are not
    to be changed in place; a new array is a new entry)."""
    key = (id(mesh.positions), id(mesh.triangles), id(mesh.normals))
    hit = _OBJECT_FACTS.get(key)
    if (
        hit is not None
        and hit[0].positions is mesh.positions
        and hit[0].triangles is mesh.triangles
        and hit[0].normals is mesh.normals
    ):
        return hit[1]
    pos, tri = mesh.positions, mesh.triangles
    used = np.zeros(len(pos), dtype=bool)
    used[tri.reshape(-1)] = True
    tol = coordinate_tolerance(pos[used]) if used.any() else 0.0
    if len(tri):
        p0 = pos[tri[:, 0]]
        fn = np.cross(pos[tri[:, 1]] - p0, pos[tri[:, 2]] - p0)
        fn_len = np.sqrt(np.einsum("ij,ij->i", fn, fn))
        good = fn_len > 0
        closed, convex = _convex_surface(pos, tri, tol)
    else:
        fn, fn_len, good = np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=bool)
        closed = convex = False
    planar = False
    if good.any():
        first = int(np.argmax(good))
        n0 = fn[first] / fn_len[first]
        planar = bool(np.all(np.abs((pos[used] - pos[tri[first, 0]]) @ n0) <= tol))
    if mesh.normals is None or not good.any():
        flat_normals = mesh.normals is None  # decided from planarity by the caller
    else:
        nrm = mesh.normals / np.maximum(np.linalg.norm(mesh.normals, axis=1, keepdims=True), 1e-300)
        unit = fn[good] / fn_len[good, None]
        cos = np.einsum("tkc,tc->tk", nrm[tri[good]], unit)
        flat_normals = bool(np.all(cos >= 1 - 1e-9))
    facts = _ObjectFacts(used, good, planar, closed, convex, flat_normals)
    if len(_OBJECT_FACTS) >= 64:
        _OBJECT_FACTS.pop(next(iter(_OBJECT_FACTS)))
    _OBJECT_FACTS[key] = (mesh, facts)
    return facts


_WORLD_FACTS: dict[tuple[int, int, int, bytes], _MeshFacts] = {}


def _mesh_facts(mesh: Mesh) -> _MeshFacts:
    """World-space facts of ``mesh``, cached by its arrays' identity and its transform."""
    obj = _object_facts(mesh)
    key = (id(mesh.positions), id(mesh.triangles), id(mesh.normals), mesh.transform.tobytes())
    hit = _WORLD_FACTS.get(key)
    if hit is not None and _OBJECT_FACTS.get(key[:3], (None, None))[1] is obj:
        return hit if hit.mesh is mesh else replace(hit, mesh=mesh)
    linear = mesh.transform[:3, :3]
    world = mesh.positions[obj.used] @ linear.T + mesh.transform[:3, 3]
    if len(world) == 0:
        return _MeshFacts(world, mesh, 0, np.zeros(3), 0.0, False, None, False, False, False)
    lo, hi = world.min(axis=0), world.max(axis=0)
    centre = (lo + hi) / 2
    radius = float(np.sqrt(np.max(np.einsum("ij,ij->i", world - centre, world - centre))))
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
        world, mesh, len(mesh.triangles), centre, radius, obj.planar, plane, obj.closed, convex, flat_normals
    )
    if len(_WORLD_FACTS) >= 64:
        _WORLD_FACTS.pop(next(iter(_WORLD_FACTS)))
    _WORLD_FACTS[key] = facts
    return facts


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


def _may_shadow(
    caster: _MeshFacts, receiver: _MeshFacts, light: DirectionalLight | PointLight | SpotLight
) -> bool:
    """Conservative: can ``caster`` lie between ``light`` and any point of ``receiver``?"""
    if caster.planar and caster.plane is not None:
        # a flat caster shades only what lies on its far side from the light
        oriented, _ = _light_side_distance(caster.plane, light)
        if float(np.min(receiver.world @ oriented[:3]) + oriented[3]) >= -_EPS * max(receiver.radius, 1.0):
            return False
    r = caster.radius + receiver.radius
    if isinstance(light, DirectionalLight):
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
    if isinstance(light, DirectionalLight):
        towards = -np.asarray(light.direction)
        if float(n @ towards) < 0:
            n, d = -n, -d
        return np.r_[n, d], math.inf
    lp = np.asarray(light.position)
    h = float(n @ lp + d)
    if h < 0:
        n, d, h = -n, -d, -h
    return np.r_[n, d], h


# --------------------------------------------------------------------------- decisions


def _lowest_opacity(scene: Scene, mesh: Mesh) -> float:
    """The lowest opacity a fragment of ``mesh`` can have, as the frame resolves it.

    Kay–Greenberg materials reach ``1 − max(t_min, t_max)`` (``Material.min_opacity``); an
    emission-model fragment has alpha 0 and hides nothing behind it (opacity 0); under
    two-sided lighting the back material counts too.
    """

    def lowest(material: Material) -> float:
        if not material.transparent:
            return 1.0
        return 0.0 if material.transparency_model == "emission" else material.min_opacity

    return min(lowest(m) for m in _sides(scene, mesh))


def _plan_transparency(scene: Scene, facts: list[_MeshFacts], tolerance: float, models: dict) -> Choice:
    opacity = [_lowest_opacity(scene, m) for m in scene.meshes]
    transparent = [i for i, m in enumerate(scene.meshes) if opacity[i] < 1.0 and len(m.triangles)]
    if not transparent:
        return Choice("zbuffer", "no transparent objects: a plain z-buffer is exact")
    simple = all(facts[i].planar or facts[i].convex for i in transparent)
    if len(transparent) == 1 and simple:
        i = transparent[0]
        shape = "planar" if facts[i].planar else "convex"
        return Choice(
            "draw_last",
            f"one transparent object (mesh {i}), {shape}: drawn after the opaque ones, back faces "
            "then front faces, is exact",
        )
    rects = {i: _screen_rect_and_depth(facts[i], scene) for i in transparent}
    conflicts = []
    for a_pos, a in enumerate(transparent):
        for b in transparent[a_pos + 1 :]:
            (ra, (na, fa)), (rb, (nb, fb)) = rects[a], rects[b]
            if _rects_overlap(ra, rb) and not (fa < nb or fb < na):
                conflicts.append((a, b))
    if simple and not conflicts:
        return Choice(
            "sort_objects",
            f"{len(transparent)} transparent planar or convex objects that never overlap in depth where "
            "they overlap on screen: sorting them back to front is exact",
        )
    why = (
        f"transparent meshes {conflicts[0][0]} and {conflicts[0][1]} overlap on screen and in depth "
        "(they may interpenetrate)"
        if conflicts
        else "a transparent object can overlap itself (neither planar nor convex)"
    )
    exact = Choice(
        "a_buffer",
        f"{why}: only a per-pixel sort (A-buffer) is exact",
        predicted_steps=0.0,
        relative_cost=1.0,
    )
    if tolerance <= 0:
        return exact
    alpha_min = min(opacity[i] for i in transparent)
    if alpha_min <= 0:
        return Choice(
            "a_buffer",
            f"{why}: a surface of opacity 0 (or the emission model) attenuates nothing behind it, so no "
            "number of peeled layers bounds the rest; the A-buffer is exact",
            predicted_steps=0.0,
            relative_cost=1.0,
        )
    # what the dropped layers hide: transparent and opaque colour behind them, and coverage (alpha)
    factors = [
        1.0 if isinstance(light, AmbientLight) else _light_factor_bound(light, facts)
        for light in scene.lights
    ]
    brightest = max(1.0, *(_max_radiance(scene, m, factors) for m in scene.meshes))
    if any(m.transparency_model == "absorption" for i in transparent for m in _sides(scene, scene.meshes[i])):
        brightest /= alpha_min  # c + (1 − α)·behind: a stack behind adds up to B·Σ(1 − α)^j ≤ B/α
    if not math.isfinite(brightest):
        return replace(
            exact,
            reason=f"{why}: a light's attenuation is unbounded at a surface (k_c + k_l·d + k_q·d² can be 0), "
            "so no number of peeled layers bounds the rest; the A-buffer is exact",
        )
    layers_bound = sum(
        1 if facts[i].planar else 2 * max(len(scene.meshes[i].triangles), 1) for i in transparent
    )
    pick = calibration.choose_depth_peeling(models, tolerance, alpha_min, brightest, layers_bound)
    c = calibration.depth_peeling_factor(models)
    if pick["method"] == "depth_peeling":
        k, err, cost = pick["layers"], pick["predicted_steps"], pick["predicted_cost"]
        return Choice(
            "depth_peeling",
            f"{why}; depth peeling, {k} layers: predicted max error {err:.2g} steps ≤ tolerance "
            f"{tolerance:g}, cost {cost:.2f}× A-buffer (255·{c:.3g}·{brightest:.3g}·(1 − {alpha_min:g})^{k})",
            {"layers": k},
            predicted_steps=err,
            relative_cost=cost,
        )
    return Choice(
        "a_buffer",
        f"{why}: no number of peeled layers is predicted within {tolerance:g} steps and faster than the "
        f"A-buffer (peeling k of at most {layers_bound} layers costs ({models['depth_peeling']['t0']:.2f} + "
        f"{models['depth_peeling']['t1']:.3f}·k)× the A-buffer); the A-buffer is exact",
        predicted_steps=0.0,
        relative_cost=1.0,
    )


def _light_factor_bound(light: DirectionalLight | PointLight | SpotLight, facts: list[_MeshFacts]) -> float:
    """Upper bound of ``att·spot`` of ``light`` over every surface point of the scene.

    ``att = 1/(k_c + k_l·d + k_q·d²)`` decreases with the distance ``d`` (``k ≥ 0``), so it is
    at most its value at ``d_min``, a lower bound of the distance from the light to any mesh:
    the distance to the nearest mesh's axis-aligned bounding box. It exceeds 1 whenever the
    denominator is below 1 there (``k_c < 1`` near the light): 100 for ``k_c = 0.01`` at
    ``d = 0``. The spot factor ``max(−l·s, 0)^e`` is at most 1. Directional lights: 1.
    Infinite when the denominator can be 0.
    """
    if isinstance(light, DirectionalLight):
        return 1.0
    pos = np.asarray(light.position, dtype=np.float64)
    d_min = math.inf
    for f in facts:
        if len(f.world) == 0:
            continue
        lo, hi = f.world.min(axis=0), f.world.max(axis=0)
        d_min = min(d_min, float(np.linalg.norm(np.maximum(np.maximum(lo - pos, pos - hi), 0.0))))
    if not math.isfinite(d_min):
        return 0.0
    denominator = light.constant + light.linear * d_min + light.quadratic * d_min * d_min
    return math.inf if denominator <= 0 else 1.0 / denominator


def _sides(scene: Scene, mesh: Mesh) -> list[Material]:
    """The materials a mesh's fragments are shaded with: the back one too under two-sided lighting."""
    if scene.light_model.two_sided and mesh.back_material is not None:
        return [mesh.material, mesh.back_material]
    return [mesh.material]


def _max_radiance(scene: Scene, mesh: Mesh, factors: list[float]) -> float:
    """Upper bound of the straight colour any fragment of ``mesh`` can have (unclamped lighting).

    Bounding every factor of the lighting equation (:mod:`blinn_phong.lighting`, OpenGL 2.1
    §2.14.1) term by term, per channel and per side's material:

    ``c ≤ e_cm + a_cm·a_cs + a_cm·Σ_amb I + Σ_i F_i·(a_cm·a_cli + d_cm·d_cli + s_cm·s_cli)``

    since ``n ⊙ l ≤ 1``, ``spec^s ≤ 1``, the visibility ``≤ 1`` and ``att_i·spot_i ≤ F_i``
    (``factors``, :func:`_light_factor_bound`, which exceeds 1 for a positional light with
    ``k_c < 1`` close to a surface). The bound is the largest channel.
    """
    worst = 0.0
    for m in _sides(scene, mesh):
        total = np.asarray(m.emission) + np.asarray(m.ambient) * np.asarray(scene.ambient)
        for light, factor in zip(scene.lights, factors, strict=True):
            if isinstance(light, AmbientLight):
                total = total + np.asarray(m.ambient) * np.asarray(light.radiance)
                continue
            if factor == 0.0:
                continue
            per_light = (
                np.asarray(m.ambient) * np.asarray(light.ambient)
                + np.asarray(m.diffuse) * np.asarray(light.diffuse)
                + np.asarray(m.specular) * np.asarray(light.specular)
            )
            total = total + factor * per_light
        worst = max(worst, float(np.max(total)))
    return worst


def _self_shadow_free(scene: Scene, f: _MeshFacts) -> str | None:
    """Why a mesh cannot shade itself (a phrase), or None when it may.

    A point ``p`` of a triangle on a supporting plane of a convex mesh, lit from the outer
    side of that plane (``n·l > 0``, ``n`` outward), sends its ray to the light into the open
    half-space beyond the plane, where no point of the mesh lies: no self-shadow. With
    one-sided lighting every fragment, back faces included, is lit with the outward normal,
    so that is every lit point. Two-sided lighting lights back faces with ``−n``, from the
    inner side, whose rays cross the mesh: they are never seen only when the mesh is closed,
    opaque (a transparent front shows the inside) and the camera outside it, which holds
    when the whole mesh lies beyond the near plane. A planar mesh never shades itself (a ray
    leaving its plane does not return to it).
    """
    if f.planar:
        return "planar"
    if not f.convex:
        return None
    if not scene.light_model.two_sided:
        return "convex, lit one-sided (inside faces with the outward normal)"
    if _lowest_opacity(scene, f.mesh) < 1.0:
        return None
    if scene.camera is not None and len(f.world):
        hom = np.c_[f.world, np.ones(len(f.world))]
        clip = hom @ (scene.camera.projection @ scene.camera.view).T
        if np.all(clip[:, 3] > 0) and np.all(clip[:, 2] > -clip[:, 3]):
            return "closed and convex, wholly beyond the near plane (its inside is never seen)"
    return None


def _projected_width(f: _MeshFacts, direction: np.ndarray) -> float:
    """Smallest extent (world units) of a mesh seen along ``direction``, the light's view.

    The vertices are projected on the plane across ``direction``; the minimum width of a
    planar point set is attained across one edge of its convex hull (rotating calipers,
    Toussaint 1983), so it is the smallest, over the hull's edges, of the extent of the hull
    along the edge's normal. 0 for a pane seen edge-on.
    """
    from scipy.spatial import ConvexHull, QhullError

    d = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    flat = np.c_[f.world @ u, f.world @ v]
    flat = flat - flat.mean(axis=0)
    try:
        hull = ConvexHull(flat)
    except (QhullError, ValueError):  # collinear or too few points: no area seen from the light
        return 0.0
    corners = flat[hull.vertices]
    along = corners @ hull.equations[:, :2].T  # (H, E): unit edge normals
    return float(np.min(along.max(axis=0) - along.min(axis=0)))


def _shadow_pairs(
    scene: Scene, facts: list[_MeshFacts], light: DirectionalLight | PointLight | SpotLight
) -> list[tuple[int, int]]:
    """Every ``(caster, receiver)`` pair of mesh indices that may shadow (``a == b``: itself)."""
    pairs = []
    for a, fa in enumerate(facts):
        if fa.n_tris == 0:
            continue
        for b, fb in enumerate(facts):
            if fb.n_tris == 0:
                continue
            if a == b:
                if _self_shadow_free(scene, fa) is None:
                    pairs.append((a, b))
            elif _may_shadow(fa, fb, light):
                pairs.append((a, b))
    return pairs


@dataclass(frozen=True)
class MapGeometry:
    """What the shadow-map models read of a scene, for one directional light (world units).

    Attributes:
        span: side of the square the map covers (the diameter of the sphere around every
            vertex, as :func:`blinn_phong.shadows.light_shadow_maps` frames it).
        feature: the thinnest caster seen from the light (:func:`_projected_width`).
        triangles: triangles in the scene (what the ray tracer's scene build scales with).
    """

    span: float
    feature: float
    triangles: int


def _map_geometry(facts: list[_MeshFacts], light: DirectionalLight, casters: set[int]) -> MapGeometry:
    world = np.concatenate([f.world for f in facts if len(f.world)])
    centre = (world.min(axis=0) + world.max(axis=0)) / 2
    span = 2.0 * float(np.sqrt(np.max(np.einsum("ij,ij->i", world - centre, world - centre))))
    direction = np.asarray(light.direction, dtype=np.float64)
    feature = min(_projected_width(facts[c], direction) for c in casters)
    return MapGeometry(span, feature, sum(f.n_tris for f in facts))


def shadow_map_geometry(scene: Scene, index: int) -> MapGeometry:
    """The :class:`MapGeometry` the planner feeds the shadow-map models for directional light ``index``.

    Used by :mod:`benchmarks.error_models` to fit the models with the planner's own inputs.
    """
    light = scene.lights[index]
    if not isinstance(light, DirectionalLight):
        raise ValueError(f"index: expected a directional light, got {type(light).__name__}")
    facts = [_mesh_facts(mesh) for mesh in scene.meshes]
    casters = {a for a, _ in _shadow_pairs(scene, facts, light)}
    if not casters:
        raise ValueError("scene: no mesh casts a shadow from this light")
    return _map_geometry(facts, light, casters)


def _plan_shadow(
    scene: Scene, facts: list[_MeshFacts], index: int, tolerance: float, models: dict, frame: _Frame
) -> Choice:
    light = scene.lights[index]
    if isinstance(light, AmbientLight):
        return Choice("none", "an ambient light has no direction and casts no shadow")
    pairs = _shadow_pairs(scene, facts, light)
    if not pairs:
        return Choice(
            "none",
            "no occluder between the light and anything: every shadow volume misses the other meshes "
            "and no mesh can shade itself (each is planar, or convex and never lit from inside)",
        )
    receivers = {b for _, b in pairs}
    casters = {a for a, _ in pairs}
    planes = [facts[b].plane for b in receivers]
    if all(facts[b].planar for b in receivers) and not (receivers & casters):
        base = planes[0]
        same_plane = all(
            abs(abs(float(p[:3] @ base[:3])) - 1) < 1e-9 and abs(abs(p[3]) - abs(base[3])) < 1e-9
            for p in planes
        )
        if same_plane:
            oriented, light_height = _light_side_distance(base, light)
            ok = True
            for a in casters:
                h = facts[a].world @ oriented[:3] + oriented[3]
                if h.min() < -1e-9 or h.max() >= light_height:
                    ok = False
            if ok and not embree_available():
                return Choice(
                    "shadow_volume",
                    f"{NO_EMBREE}, instead of planar projected shadows (which test points against the "
                    f"casters with it); only the plane of mesh {min(receivers)} receives shadows",
                    predicted_steps=0.0,
                )
            if ok:
                return Choice(
                    "planar",
                    f"only the plane of mesh {min(receivers)} receives shadows and every caster lies between "
                    "it and the light: projected (fake) shadows are exact",
                    {"plane": tuple(float(v) for v in oriented)},
                )
    a, b = pairs[0]
    if a == b:
        why_self = (
            "open or not convex"
            if not facts[a].convex
            else "two-sided lighting lights its inside, which may be seen"
        )
        what = f"mesh {a} can shade itself ({why_self})"
    else:
        what = f"mesh {a} can shadow mesh {b}"
    # The tolerance bounds every pixel: a sample classified differently from the ray tracer
    # (a shadow map's misplaced edge, a shadow volume's grazing sample) costs the light's whole
    # lit-minus-shadowed contribution there, so such a method is allowed only when that fits.
    weight = _shadow_weight(scene, light, facts)
    worst = 255.0 * weight
    exact = _exact_shadow(what, models, frame, sum(f.n_tris for f in facts), tolerance, worst)
    if tolerance <= 0:
        return exact
    if not isinstance(light, DirectionalLight):
        return replace(
            exact, reason=f"{exact.reason}; the shadow-map models are calibrated for directional lights only"
        )
    if worst > tolerance:
        return replace(
            exact,
            reason=f"{exact.reason}; a shadow map can misplace a hard edge, where a pixel changes by the "
            f"light's whole contribution, up to {worst:.3g} steps > tolerance {tolerance:g}",
        )
    geometry = _map_geometry(facts, light, casters)
    span, feature = geometry.span, geometry.feature
    if span <= 0 or feature <= 0:
        return replace(
            exact,
            reason=f"{exact.reason}; a caster has no width seen from the light (a pane edge-on), which no "
            "shadow-map resolution resolves",
        )
    pick = calibration.choose_shadow_map(
        models,
        tolerance,
        span,
        feature,
        1.0,
        weight,
        receivers=frame.receivers,
        triangles=geometry.triangles,
    )
    exact_cost = 1.0 if exact.relative_cost is None else exact.relative_cost
    if pick["method"] == "shadow_map" and pick["predicted_cost"] < exact_cost:
        res, cost = pick["resolution"], pick["predicted_cost"]
        return Choice(
            "shadow_map",
            f"{what}; a {res}² shadow map: every pixel within the light's contribution {worst:.3g} steps "
            f"≤ tolerance {tolerance:g}; texel {span / res:.3g} ≤ half the thinnest caster seen from the "
            f"light ({feature:.3g}); predicted mean {pick['predicted_mean']:.2g} steps, cost {cost:.2f}× "
            f"ray tracing for {frame.receivers} receiver samples"
            + (f" (shadow volumes: {exact_cost:.2f}×)" if exact.method == "shadow_volume" else ""),
            {"resolution": res},
            predicted_steps=worst,
            relative_cost=cost,
        )
    if pick["method"] == "shadow_map":
        return replace(
            exact,
            reason=f"{exact.reason}; the cheapest shadow map resolving every caster ({pick['resolution']}²) "
            f"is predicted at {pick['predicted_cost']:.2f}× ray tracing, not below {exact_cost:.2f}×",
        )
    return replace(
        exact,
        reason=f"{exact.reason}; no shadow map with texels of at most half the thinnest caster seen from "
        f"the light ({feature:.3g} of a {span:.3g} span) is predicted faster for {frame.receivers} "
        "receiver samples",
    )


def coloured_shadow_reason(scene: Scene, choice: Choice) -> Choice:
    """``choice`` with its reason saying how transparent casters shadow (coloured only when ray traced).

    Args:
        scene: the scene planned for.
        choice: one light's shadow choice.

    Returns:
        ``choice`` unchanged when its method is ``none`` or no caster lets light through
        (:func:`blinn_phong.shadows.mesh_shadow_transmittance`); else with "; coloured shadows: …"
        (``ray_traced``) or "; transparent meshes … cast full shadows" (the binary methods) appended.
    """
    if choice.method == "none":
        return choice
    from .shadows import mesh_shadow_transmittance  # one definition, shared with the renderer

    two_sided = scene.light_model.two_sided
    lets_through = [
        i
        for i, mesh in enumerate(scene.meshes)
        if mesh.casts_shadows and mesh_shadow_transmittance(mesh, two_sided).any()
    ]
    if not lets_through:
        return choice
    which = ", ".join(str(i) for i in lets_through)
    if choice.method == "ray_traced":
        return replace(choice, reason=f"{choice.reason}; coloured shadows: light crossing transparent "
                       f"meshes {which} keeps their transmittance per RGB channel")  # fmt: skip
    return replace(choice, reason=f"{choice.reason}; transparent meshes {which} cast full shadows "
                   f"({choice.method} is binary; coloured shadows are ray traced)")  # fmt: skip


def embree_available() -> bool:
    """True when ``embreex`` (Intel Embree) can be imported; Blender's own Python lacks it.

    Ray-traced and planar shadows cast rays with it; without it the planner picks shadow
    volumes, exact too, for hard shadows.
    """
    try:
        import embreex  # noqa: F401
    except ImportError:
        return False
    return True


#: Why a plan without Embree uses shadow volumes (the start of the choice's reason).
NO_EMBREE = "Embree (embreex) is not installed: shadow volumes, exact too"


def _exact_shadow(
    what: str, models: dict, frame: _Frame, triangles: int, tolerance: float, worst: float
) -> Choice:
    """The cheaper predicted exact hard-shadow method: Embree ray tracing or shadow volumes.

    Shadow volumes where Embree cannot be imported; otherwise the one the cost model
    (:func:`blinn_phong.calibration.shadow_volume_cost`, for the scene's ``triangles`` and the
    frame's receiver samples) predicts faster, ray tracing on a tie or without a model.
    ``relative_cost`` is relative to ray tracing.

    Both methods are exact, but they are different computations: on samples whose shadow ray
    grazes a caster's silhouette they may disagree (and the planner fuzzer measured further
    disagreements on random scenes: docs/speed_accuracy.md). The tolerance is measured
    against the ray tracer's image, so shadow volumes replace an available Embree only when
    ``worst`` — 255 times the light's whole lit-minus-shadowed contribution, what one
    differently classified sample can cost a pixel — is within ``tolerance``.
    """
    costs = calibration.shadow_volume_cost(models, triangles, frame.receivers)
    where = f"for {triangles} triangles and {frame.receivers} receiver samples"
    if not embree_available():
        predicted = f" (predicted {costs['shadow_volume'] * 1e3:.3g} ms {where})" if costs is not None else ""
        return Choice(
            "shadow_volume",
            f"{what}: {NO_EMBREE}, instead of ray tracing{predicted}",
            predicted_steps=0.0,
            relative_cost=None if costs is None else costs["ratio"],
        )
    if costs is None:
        return Choice(
            "ray_traced", f"{what}: ray-traced shadows are exact", predicted_steps=0.0, relative_cost=1.0
        )
    volume, traced, ratio = costs["shadow_volume"] * 1e3, costs["ray_traced"] * 1e3, costs["ratio"]
    if ratio < 1.0 and worst > tolerance:
        return Choice(
            "ray_traced",
            f"{what}: ray-traced shadows are exact; shadow volumes, predicted faster ({volume:.3g} ms "
            f"against {traced:.3g} ms, {ratio:.2f}×, {where}), may classify a grazing sample differently, "
            f"where a pixel changes by the light's whole contribution, up to {worst:.3g} steps > tolerance "
            f"{tolerance:g}",
            predicted_steps=0.0,
            relative_cost=1.0,
        )
    if ratio < 1.0:
        return Choice(
            "shadow_volume",
            f"{what}: shadow volumes are exact and predicted faster than Embree ray tracing, "
            f"{volume:.3g} ms against {traced:.3g} ms ({ratio:.2f}×) {where}; a sample they classify "
            f"differently changes a pixel by at most {worst:.3g} steps ≤ tolerance {tolerance:g}",
            predicted_steps=worst,
            relative_cost=ratio,
        )
    return Choice(
        "ray_traced",
        f"{what}: ray-traced shadows are exact and predicted faster than shadow volumes, "
        f"{traced:.3g} ms against {volume:.3g} ms ({ratio:.2f}× ray tracing) {where}",
        predicted_steps=0.0,
        relative_cost=1.0,
    )


def _shadow_weight(
    scene: Scene, light: DirectionalLight | PointLight | SpotLight, facts: list[_MeshFacts]
) -> float:
    """Largest change of a pixel channel between lit and shadowed by ``light``: over every side's
    material, ``F·(d_cm·d_cl + s_cm·s_cl)`` with ``F`` the bound of ``att·spot``
    (:func:`_light_factor_bound`), since ``n ⊙ l ≤ 1`` and the specular factor ``≤ 1``; the
    light's ambient term is not shadowed."""
    factor = _light_factor_bound(light, facts)
    weight = 0.0
    for mesh in scene.meshes:
        for m in _sides(scene, mesh):
            term = np.asarray(m.diffuse) * np.asarray(light.diffuse)
            term = term + np.asarray(m.specular) * np.asarray(light.specular)
            weight = max(weight, float(np.max(term)))
    return factor * weight


def _plan_shading(
    scene: Scene, facts: list[_MeshFacts], index: int, tolerance: float, models: dict
) -> Choice:
    mesh = scene.meshes[index]
    if mesh.shading is not None:
        return Choice(mesh.shading, "set on the mesh by the caller")
    positional = [type(light).__name__ for light in scene.lights if isinstance(light, PointLight | SpotLight)]
    infinite_viewer = not scene.light_model.local_viewer
    if not facts[index].flat_normals:
        choice = Choice("phong", "normals vary across faces: per-pixel shading is the reference")
    elif positional:
        choice = Choice(
            "phong", f"planar faces, but a {positional[0]} changes the light direction across each face"
        )
    elif not infinite_viewer:
        choice = Choice(
            "phong",
            "planar faces, but a local viewer changes the view direction across each face "
            "(an orthographic camera should set LightModel(local_viewer=False))",
        )
    else:
        return Choice(
            "flat",
            "planar faces under directional light with a distant viewer: lighting is constant per face, "
            "flat shading is exact",
        )
    if tolerance <= 0 or len(mesh.triangles) == 0 or facts[index].flat_normals:
        return choice  # the shading model is calibrated on curved meshes (vertex normals that vary)
    calibrated = models["shading"]["shininess_calibrated"]
    if mesh.material.shininess > calibrated:
        return Choice(
            "phong",
            f"{choice.reason}; shininess {mesh.material.shininess:g} is beyond the calibrated {calibrated:g}",
        )
    theta = calibration.max_normal_angle(_world_normals(mesh), mesh.triangles)
    theta_max = min(m["theta_range"][1] for m in models["shading"]["methods"].values())
    if theta > theta_max:
        return Choice(
            "phong",
            f"{choice.reason}; adjacent normals {math.degrees(theta):.3g}° apart, beyond the calibrated "
            f"{math.degrees(theta_max):.3g}°",
        )
    pick = calibration.choose_shading(models, tolerance, theta)
    err, cost = pick["predicted_steps"], pick["predicted_cost"]
    if pick["method"] != "phong":
        return Choice(
            pick["method"],
            f"{pick['method']} shading: predicted max error {err:.2g} steps ≤ tolerance {tolerance:g}, "
            f"cost {cost:.2f}× Phong (adjacent normals up to {math.degrees(theta):.3g}° apart)",
            {},
            predicted_steps=err,
            relative_cost=cost,
        )
    methods = models["shading"]["methods"]
    others = ", ".join(
        f"{name} {calibration.predict_shading(models, name, theta):.2g} steps at "
        f"{methods[name]['ratio_to_phong']:.2f}×"
        for name in ("flat", "gouraud")
    )
    return Choice(
        "phong",
        f"{choice.reason}; predicted: {others} Phong's time, none both within {tolerance:g} steps and faster",
        predicted_steps=err,
        relative_cost=1.0,
    )


def _world_normals(mesh: Mesh) -> np.ndarray:
    """Vertex normals in world space (the inverse transpose of the linear part), as the renderer uses them."""
    normals = mesh.normals if mesh.normals is not None else vertex_normals(mesh.positions, mesh.triangles)
    return np.asarray(normals, dtype=np.float64) @ np.linalg.inv(mesh.transform[:3, :3])


#: The frame assumed when :func:`plan` is not told one (receiver samples for the cost models).
DEFAULT_FRAME = (640, 480, 1)


@dataclass(frozen=True)
class _Frame:
    width: int
    height: int
    samples: int

    @property
    def receivers(self) -> int:
        """Shading samples of the frame, ``width·height·samples²`` (the points that need a visibility)."""
        return self.width * self.height * self.samples**2


def _frame(width: int | None, height: int | None, samples: int) -> _Frame:
    w = DEFAULT_FRAME[0] if width is None else width
    h = DEFAULT_FRAME[1] if height is None else height
    for name, value in (("width", w), ("height", h), ("samples", samples)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return _Frame(int(w), int(h), int(samples))


def plan(
    scene: Scene,
    tolerance: float = 0.0,
    models: dict | None = None,
    *,
    width: int | None = None,
    height: int | None = None,
    samples: int = 1,
) -> Plan:
    """Pick, per concern, the fastest method that is exact or predicted within ``tolerance`` for ``scene``.

    Args:
        scene: the scene to plan for.
        tolerance: acceptable error in 8-bit steps (1/255 of the unit range), ≥ 0: a bound on
            every channel of every pixel of the image against the image every exact method
            gives (docs/speed_accuracy.md, "What the tolerance promises"). 0 asks for exact
            methods only.
        models: error and cost models (default: :func:`blinn_phong.calibration.shipped_models`,
            fitted to ``python -m benchmarks`` measurements).
        width: frame width in pixels (None: :data:`DEFAULT_FRAME`), as passed to ``render``.
        height: frame height in pixels (None: :data:`DEFAULT_FRAME`).
        samples: ``k`` for k×k samples per pixel, as passed to ``render``.

    ``render(scene, width, height, samples=k, tolerance=T)`` follows
    ``plan(scene, T, width=width, height=height, samples=k)`` wherever the caller sets no
    method (:func:`blinn_phong.frame.frame_plan`); the frame matters only to the cost models.

    Returns:
        :class:`Plan` with a choice and a reason per concern; approximate choices carry their
        predicted error and cost relative to the exact method.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a blinn_phong.Scene, got {type(scene).__name__}")
    if isinstance(tolerance, bool) or not (
        isinstance(tolerance, int | float) and math.isfinite(tolerance) and tolerance >= 0
    ):
        raise ValueError(f"tolerance must be a finite number of 8-bit steps >= 0, got {tolerance!r}")
    tol = float(tolerance)
    frame = _frame(width, height, samples)
    m = models if models is not None else calibration.shipped_models()
    facts = [_mesh_facts(mesh) for mesh in scene.meshes]
    transparency = _plan_transparency(scene, facts, tol, m)
    shadows = tuple(_plan_shadow(scene, facts, i, tol, m, frame) for i in range(len(scene.lights)))
    shadows = tuple(coloured_shadow_reason(scene, c) for c in shadows)
    shading = tuple(_plan_shading(scene, facts, i, tol, m) for i in range(len(scene.meshes)))
    return Plan(transparency, shadows, shading, tol)
