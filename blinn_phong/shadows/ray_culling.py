"""Which hard shadow rays can be answered without tracing them, and their answer.

Compiled (numba): imported by the frame pipeline only when numba is available; the numpy
engine traces every ray, and so is the reference this module is tested against.

A frame's hard ray-traced shadows cast one ray per visible sample and light
(:func:`blinn_phong.shadows.raytrace.directional_light_visibility`,
:func:`blinn_phong.shadows.raytrace.point_light_visibility`). Most of those rays have an answer that
geometry alone proves: a ground plane's samples far from every object are lit, the dark side of
a convex object is shadowed by it, samples deep in a ball's shadow are shadowed. This module
finds them with a few float64 tests per ray, so that Embree traces only the rest. The ray is the
one :func:`blinn_phong.shadows.ray_setup_kernels.hard_shadow_rays` builds: origin ``o = p + s·eff·n`` (``n``
the unit face normal, ``s = ±1`` towards the light, ``eff = max(offset, ulps·‖p − c₀‖∞)``, ``c₀``
the BVH's centre), unit direction ``d`` from ``o`` towards the light, ``0 < t < t_max``.

**Its own mesh** (when that mesh casts shadows):

* a *planar* mesh, every vertex within ``dev`` of the plane ``m·x = k``: with ``m`` turned
  towards the origin's side (``m·s·n > 0``), ``m·d ≥ 0`` and ``eff·(m·s·n) > 2·dev + margin``,
  every ray point lies more than ``dev`` above the plane, so off every triangle: no hit;
* a *convex* closed mesh ``K`` wound outwards (:mod:`blinn_phong.geometry.mesh_facts`), with a ball
  ``B(c, r_in)`` inside it and ``B(c, r_out)`` around it (``r_in`` the smallest distance from
  ``c`` to a face plane, minus the tolerances below): ``K`` lies in the half-space
  ``n·(x − p) ≤ dev`` of each face, so with the light on the face's outer side (``s = +1``),
  ``n·d ≥ 0`` and ``eff > 2·dev + margin`` no ray point is in ``K``: no hit. With the light
  on its inner side (``s = −1``), outside ``B(c, r_out)`` by more than ``eff``, and the origin
  inside the cone from ``p`` around ``B(c, r_in)`` (which ``K``, convex, contains): the ray
  leaves ``K`` before the light: a hit, *shadowed*;
* any other mesh: trace.

**Every other caster** (not needed where its padded bounding box is missed: Kay & Kajiya's slab
test on ``[0, t_max]``): for a convex caster, the point of the segment closest to ``c``; farther
than ``r_out`` from it: no hit; nearer than ``r_in`` while the origin is outside ``B(c, r_out)``:
the segment enters ``K`` before that point, a hit, *shadowed*. Otherwise trace.

``margin`` and ``pad`` are ``16·2⁻²³·R`` (``R`` the casters' largest distance from ``c₀`` in the
∞-norm): Embree intersects float32 triangles with float32 rays, whose rounding moves a triangle
or a ray point by a few ``2⁻²³·R``; every test keeps a clearance larger than that (the balls are
shrunk and grown by it), so Embree gives the same answer. The one caveat is Embree's own:
its default triangle test is not watertight, so a ray crossing a closed mesh exactly through a
shared edge (within float32 rounding, at both of its crossings) could slip through where this
module says shadowed — the geometrically right answer. The tests compare both answers sample
for sample.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from blinn_phong.geometry.mesh_facts import _mesh_facts, coordinate_tolerance
from blinn_phong.model.scene import Scene
from compositing._threads import in_shares

__all__ = ["LIT", "SHADOWED", "TRACE", "caster_tables", "rays_to_trace"]

#: Mesh kinds of :func:`caster_tables`: not a caster, a caster that may stop its own rays, planar, convex.
NOT_CASTER, GENERAL, PLANAR, CONVEX = 0, 1, 2, 3


#: Ray answers of :func:`rays_to_trace`.
TRACE, LIT, SHADOWED = 0, 1, 2

#: Inscribed-ball radii of convex meshes, by the mesh's arrays' identity and transform.
_BALLS: dict[tuple, tuple[object, float]] = {}


def _inscribed_radius(mesh: object, facts: object, centre: np.ndarray) -> float:
    """Smallest distance from ``centre`` to the plane of a (convex, outward) mesh's face; ≤ 0 if
    ``centre`` is not inside every face's half-space."""
    key = (id(mesh.positions), id(mesh.triangles), mesh.transform.tobytes())  # type: ignore[attr-defined]
    hit = _BALLS.get(key)
    if hit is not None and hit[0] is mesh.positions:  # type: ignore[attr-defined]
        return hit[1]
    tris = facts.tris  # type: ignore[attr-defined]
    normal = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    length = np.linalg.norm(normal, axis=1)
    good = length > 0
    distance = np.einsum("ij,ij->i", normal[good], tris[good, 0] - centre) / length[good]
    radius = float(distance.min()) if len(distance) else 0.0
    if len(_BALLS) > 64:
        _BALLS.clear()
    _BALLS[key] = (mesh.positions, radius)  # type: ignore[attr-defined]
    return radius


def caster_tables(scene: Scene, centre: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per mesh of ``scene``: the facts :func:`rays_to_trace` reads.

    Args:
        scene: the frame's scene (meshes with ``casts_shadows``).
        centre: (3,) the BVH's centre (:attr:`blinn_phong.shadows.raytrace.RayScene.centre`).

    Returns:
        ``(kind, lo, hi, plane, dev, ball, pad)``: ``kind`` (M,) int64 (:data:`NOT_CASTER`,
        :data:`GENERAL`, :data:`PLANAR`, :data:`CONVEX`); ``lo``, ``hi`` (M, 3) world bounding
        boxes; ``plane`` (M, 4) unit ``(m, −k)`` of planar meshes; ``dev`` (M,) world distance
        bound of the kind's test; ``ball`` (M, 5) ``(c, r_in, r_out)`` of convex meshes, the
        radii already shrunk and grown by ``pad + dev`` (``r_in`` 0 where no ball fits); and
        the scalar ``pad`` (world units) as a (1,) array.
    """
    m = len(scene.meshes)
    kind = np.zeros(m, np.int64)
    lo = np.zeros((m, 3))
    hi = np.zeros((m, 3))
    plane = np.zeros((m, 4))
    dev = np.zeros(m)
    ball = np.zeros((m, 5))
    reach = 0.0
    convex = []
    for i, mesh in enumerate(scene.meshes):
        if not mesh.casts_shadows or len(mesh.triangles) == 0:
            continue
        facts = _mesh_facts(mesh)
        if len(facts.world) == 0:
            continue
        kind[i] = GENERAL
        lo[i], hi[i] = facts.lo, facts.hi
        reach = max(reach, float(np.abs(facts.lo - centre).max()), float(np.abs(facts.hi - centre).max()))
        if facts.planar and facts.plane is not None:
            kind[i] = PLANAR
            plane[i] = facts.plane
            dev[i] = float(np.abs(facts.world @ facts.plane[:3] + facts.plane[3]).max())
        elif facts.convex:
            kind[i] = CONVEX
            scale = float(np.linalg.norm(mesh.transform[:3, :3], 2))  # largest stretch of the model matrix
            dev[i] = 4.0 * coordinate_tolerance(mesh.positions) * scale
            convex.append((i, mesh, facts))
    pad = 16.0 * float(np.finfo(np.float32).eps) * reach
    for i, mesh, facts in convex:
        r_in = _inscribed_radius(mesh, facts, facts.centre) - dev[i] - pad
        ball[i] = (*facts.centre, max(r_in, 0.0), facts.radius + dev[i] + pad)
    return kind, lo, hi, plane, dev, ball, np.array([pad])


def rays_to_trace(
    points: np.ndarray,
    normals: np.ndarray,
    mesh_of: np.ndarray,
    light: np.ndarray,
    positional: bool,
    centre: np.ndarray,
    offset: float,
    ulps: float,
    tables: tuple[np.ndarray, ...],
) -> np.ndarray:
    """(n,) int8 answer per point's shadow ray: :data:`TRACE`, :data:`LIT` or :data:`SHADOWED`.

    Args:
        points: (n, 3) float64 world points.
        normals: (n, 3) float64 their unit face normals (as given to the ray set-up; zero for a
            zero-area face).
        mesh_of: (n,) int64 index of each point's mesh in the scene.
        light: (3,) unit direction towards a directional light, or a point light's position.
        positional: True for a point (or spot) light.
        centre: (3,) the BVH's centre.
        offset: smallest ray-origin offset (world units).
        ulps: the offset's scale with ``‖p − centre‖∞`` (``OFFSET_ULPS · 2⁻²³``).
        tables: :func:`caster_tables` of the scene.

    Returns:
        (n,) int8, by the tests of the module docstring.
    """
    kind, lo, hi, plane, dev, ball, pad = tables
    out = np.empty(len(points), np.int8)
    rays_to_trace_kernel(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(normals, dtype=np.float64),
        np.ascontiguousarray(mesh_of, dtype=np.int64),
        np.ascontiguousarray(light, dtype=np.float64),
        bool(positional),
        np.ascontiguousarray(centre, dtype=np.float64),
        float(offset),
        float(ulps),
        kind,
        lo,
        hi,
        plane,
        dev,
        ball,
        float(pad[0]),
        out,
    )
    return out


@numba.njit(inline="always", cache=True)
def _slab(o, d, inv, a, b, t0, t1):  # pragma: no cover - compiled
    """The parameter interval ``[t0, t1]`` cut by the slab ``a ≤ o + t·d ≤ b`` (empty: t0 > t1)."""
    if d == 0.0:
        if o < a or o > b:
            return 1.0, 0.0
        return t0, t1
    ta, tb = (a - o) * inv, (b - o) * inv
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _rays_to_trace_kernel_share(
    share,
    points,
    normals,
    mesh_of,
    light,
    positional,
    centre,
    offset,
    ulps,
    kind,
    lo,
    hi,
    plane,
    dev,
    ball,
    pad,
    out,
):  # pragma: no cover - compiled
    """The tests of the module docstring per point, in parallel (see :func:`rays_to_trace`)."""
    margin = pad
    for i in share:
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        # the ray of ray_setup_kernels.hard_shadow_rays, in float64
        mag = max(abs(px - centre[0]), abs(py - centre[1]), abs(pz - centre[2]))
        eff = max(offset, ulps * mag)
        length = nx * nx + ny * ny + nz * nz  # unit normals (face normals) or zero
        if positional:
            lx, ly, lz = light[0] - px, light[1] - py, light[2] - pz
        else:
            lx, ly, lz = light[0], light[1], light[2]
        s = -1.0 if nx * lx + ny * ly + nz * lz < 0 else 1.0
        ox, oy, oz = px + nx * (s * eff), py + ny * (s * eff), pz + nz * (s * eff)
        if positional:
            dx, dy, dz = light[0] - ox, light[1] - oy, light[2] - oz
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            if dist > 0:
                dx, dy, dz = dx / dist, dy / dist, dz / dist
            t_max = max(dist - eff, 0.0)
        else:
            dx, dy, dz = lx, ly, lz
            t_max = math.inf
        own = mesh_of[i]
        k = kind[own]
        answer = LIT
        if k == GENERAL or (k != NOT_CASTER and length == 0):
            answer = TRACE
        elif k == PLANAR:
            mx, my, mz = plane[own, 0], plane[own, 1], plane[own, 2]
            facing = s * (mx * nx + my * ny + mz * nz)
            if facing < 0:
                mx, my, mz, facing = -mx, -my, -mz, -facing
            if not (mx * dx + my * dy + mz * dz >= 0 and eff * facing > 2 * dev[own] + margin):
                answer = TRACE
        elif k == CONVEX:
            clear = eff > 2 * dev[own] + margin
            if s > 0:
                if not (nx * dx + ny * dy + nz * dz >= 0 and clear):
                    answer = TRACE
            else:
                answer = TRACE
                cx, cy, cz, r_in, r_out = ball[own, 0], ball[own, 1], ball[own, 2], ball[own, 3], ball[own, 4]
                light_out = True
                if positional:
                    ex, ey, ez = light[0] - cx, light[1] - cy, light[2] - cz
                    light_out = math.sqrt(ex * ex + ey * ey + ez * ez) > r_out + eff
                ux, uy, uz = cx - px, cy - py, cz - pz
                to_centre = math.sqrt(ux * ux + uy * uy + uz * uz)
                if clear and light_out and r_in > 0 and to_centre > r_in and eff < to_centre - r_in:
                    # the origin p − eff·n inside the cone from p around B(c, r_in): the angle
                    # between −n and c − p below the cone's half-angle asin(r_in / |c − p|)
                    cos_angle = -(nx * ux + ny * uy + nz * uz) / to_centre
                    sin_half = r_in / to_centre
                    if cos_angle > 0 and cos_angle * cos_angle > 1.0 - sin_half * sin_half:
                        answer = SHADOWED
        if answer == LIT:
            ix = 1.0 / dx if dx != 0.0 else math.inf
            iy = 1.0 / dy if dy != 0.0 else math.inf
            iz = 1.0 / dz if dz != 0.0 else math.inf
            for c in range(kind.shape[0]):
                if c == own or kind[c] == NOT_CASTER:
                    continue
                if kind[c] == CONVEX:  # the balls first: no division, and tighter than the box
                    cx, cy, cz, r_in, r_out = ball[c, 0], ball[c, 1], ball[c, 2], ball[c, 3], ball[c, 4]
                    wx, wy, wz = cx - ox, cy - oy, cz - oz
                    tc = min(max(wx * dx + wy * dy + wz * dz, 0.0), t_max)
                    qx, qy, qz = ox + tc * dx - cx, oy + tc * dy - cy, oz + tc * dz - cz
                    near2 = qx * qx + qy * qy + qz * qz
                    if near2 > r_out * r_out:
                        continue  # the bounding ball is missed: no hit on this caster
                    if near2 < r_in * r_in and wx * wx + wy * wy + wz * wz > r_out * r_out:
                        answer = SHADOWED  # enters K before the inscribed ball: final
                        break
                t0, t1 = 0.0, t_max
                t0, t1 = _slab(ox, dx, ix, lo[c, 0] - pad, hi[c, 0] + pad, t0, t1)
                t0, t1 = _slab(oy, dy, iy, lo[c, 1] - pad, hi[c, 1] + pad, t0, t1)
                t0, t1 = _slab(oz, dz, iz, lo[c, 2] - pad, hi[c, 2] + pad, t0, t1)
                if t0 > t1:
                    continue  # the padded box is missed: no hit on this caster
                answer = TRACE  # keep looking: another caster may prove the shadow
        out[i] = answer


def rays_to_trace_kernel(points: np.ndarray, *args: object) -> None:
    """The compiled :func:`_rays_to_trace_kernel_share` (same arguments, without ``share``) over every row, in
    shares on threads (:func:`compositing._threads.in_shares`)."""
    in_shares(_rays_to_trace_kernel_share, points.shape[0], points, *args)
