"""Which hard shadow rays can be answered without tracing them: provably unoccluded ones.

Compiled (numba): imported by the frame pipeline only when numba is available; the numpy
engine traces every ray, and so is the reference this module is tested against.

A frame's hard ray-traced shadows cast one ray per visible sample and light
(:func:`blinn_phong.raytrace.directional_light_visibility`,
:func:`blinn_phong.raytrace.point_light_visibility`). Most of those rays cannot hit anything:
a ground plane's samples far from every other object, the lit side of a convex object. This
module finds such rays with a few float64 tests per ray, so that Embree traces only the rest;
the visibility of a skipped ray is 1, the answer Embree would give. The ray is the one
:func:`blinn_phong.shadow_kernels.hard_shadow_rays` builds: origin ``o = p + s·eff·n`` (``n`` the
unit face normal, ``s = ±1`` towards the light, ``eff = max(offset, ulps·‖p − c‖∞)``), unit
direction ``d`` from ``o`` towards the light, ``0 < t < t_max``.

A ray needs tracing unless both hold:

1. **Its own mesh cannot stop it** (when that mesh casts shadows):

   * a *planar* mesh, every vertex within ``dev`` of the plane ``m·x = k``: with ``m`` turned
     towards the origin's side (``m·s·n > 0``), ``m·d ≥ 0`` and ``eff·(m·s·n) > 2·dev + margin``,
     every ray point lies more than ``dev`` above the plane, so off every triangle;
   * a *convex* closed mesh wound outwards (:mod:`blinn_phong.mesh_facts`), the light on the
     face's outer side (``s = +1``): the solid lies in the half-space ``n·(x − p) ≤ dev`` of
     each face (``dev`` four times the convexity test's tolerance in world units), and with
     ``n·d ≥ 0`` and ``eff > 2·dev + margin`` every ray point has ``n·(x − p) ≥ eff``;
   * any other mesh: trace.

2. **It misses every other caster's bounding box**, padded by ``pad``: the slab test
   (Kay & Kajiya 1986) on the segment ``[0, t_max]``; a triangle inside a box the segment
   misses cannot be hit.

``margin`` and ``pad`` are ``16·2⁻²³·R`` (``R`` the casters' largest distance from the BVH's
centre, in the ∞-norm): Embree intersects float32 triangles with float32 rays, whose
rounding moves a triangle or a ray point by a few ``2⁻²³·R``; the tests above keep a clearance
larger than that, so Embree answers a skipped ray "not occluded" too. The skipped and the
traced answers are therefore the same, sample for sample (tested against tracing every ray).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from blinn_phong.mesh_facts import _mesh_facts, coordinate_tolerance
from blinn_phong.scene import Scene

__all__ = ["caster_tables", "rays_to_trace"]

#: Mesh kinds of :func:`caster_tables`: not a caster, a caster that may stop its own rays, planar, convex.
NOT_CASTER, GENERAL, PLANAR, CONVEX = 0, 1, 2, 3


def caster_tables(scene: Scene, centre: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per mesh of ``scene``: ``(kind, lo, hi, plane, dev, pad)`` for :func:`rays_to_trace`.

    Args:
        scene: the frame's scene (meshes with ``casts_shadows``).
        centre: (3,) the BVH's centre (:attr:`blinn_phong.raytrace.RayScene.centre`).

    Returns:
        ``kind`` (M,) int64 (:data:`NOT_CASTER`, :data:`GENERAL`, :data:`PLANAR`,
        :data:`CONVEX`); ``lo``, ``hi`` (M, 3) world bounding boxes; ``plane`` (M, 4) unit
        ``(m, −k)`` of planar meshes; ``dev`` (M,) world distance bound of the kind's test; and
        the scalar ``pad`` (world units) as a (1,) array.
    """
    m = len(scene.meshes)
    kind = np.zeros(m, np.int64)
    lo = np.zeros((m, 3))
    hi = np.zeros((m, 3))
    plane = np.zeros((m, 4))
    dev = np.zeros(m)
    reach = 0.0
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
    pad = 16.0 * float(np.finfo(np.float32).eps) * reach
    return kind, lo, hi, plane, dev, np.array([pad])


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
    """(n,) bool: True where the shadow ray of a point may be occluded (trace it), by the module's tests.

    Args:
        points: (n, 3) float64 world points.
        normals: (n, 3) float64 their face normals (as given to the ray set-up).
        mesh_of: (n,) int64 index of each point's mesh in the scene.
        light: (3,) unit direction towards a directional light, or a point light's position.
        positional: True for a point (or spot) light.
        centre: (3,) the BVH's centre.
        offset: smallest ray-origin offset (world units).
        ulps: the offset's scale with ``‖p − centre‖∞`` (``OFFSET_ULPS · 2⁻²³``).
        tables: :func:`caster_tables` of the scene.

    Returns:
        (n,) bool.
    """
    kind, lo, hi, plane, dev, pad = tables
    out = np.empty(len(points), np.bool_)
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


@numba.njit(parallel=True, cache=True)
def rays_to_trace_kernel(
    points, normals, mesh_of, light, positional, centre, offset, ulps, kind, lo, hi, plane, dev, pad, out
):  # pragma: no cover - compiled
    """The tests of the module docstring per point, in parallel (see :func:`rays_to_trace`)."""
    margin = pad
    for i in numba.prange(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        # the ray of shadow_kernels.hard_shadow_rays, in float64
        mag = max(abs(px - centre[0]), abs(py - centre[1]), abs(pz - centre[2]))
        eff = max(offset, ulps * mag)
        length = math.sqrt(nx * nx + ny * ny + nz * nz)
        if length > 0:
            nx, ny, nz = nx / length, ny / length, nz / length
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
        trace = False
        if k == GENERAL or (k != NOT_CASTER and length == 0):
            trace = True
        elif k == PLANAR:
            mx, my, mz = plane[own, 0], plane[own, 1], plane[own, 2]
            facing = s * (mx * nx + my * ny + mz * nz)
            if facing < 0:
                mx, my, mz, facing = -mx, -my, -mz, -facing
            trace = not (mx * dx + my * dy + mz * dz >= 0 and eff * facing > 2 * dev[own] + margin)
        elif k == CONVEX:
            trace = not (s > 0 and nx * dx + ny * dy + nz * dz >= 0 and eff > 2 * dev[own] + margin)
        if not trace:
            # slab test of o + t·d, 0 <= t <= t_max, against each other caster's padded box
            ix = 1.0 / dx if dx != 0.0 else math.inf
            iy = 1.0 / dy if dy != 0.0 else math.inf
            iz = 1.0 / dz if dz != 0.0 else math.inf
            for c in range(kind.shape[0]):
                if c == own or kind[c] == NOT_CASTER:
                    continue
                t0, t1 = 0.0, t_max
                t0, t1 = _slab(ox, dx, ix, lo[c, 0] - pad, hi[c, 0] + pad, t0, t1)
                t0, t1 = _slab(oy, dy, iy, lo[c, 1] - pad, hi[c, 1] + pad, t0, t1)
                t0, t1 = _slab(oz, dz, iz, lo[c, 2] - pad, hi[c, 2] + pad, t0, t1)
                if t0 <= t1:
                    trace = True
                    break
        out[i] = trace
