"""Compiled (numba) set-up of ray-traced shadows: the receivers' surface and their shadow rays.

The twins of the numpy set-up of :mod:`blinn_phong.shadows.raytrace`, each a serial loop over
shares of the rows on threads (:func:`compositing._threads.in_shares`):

* :func:`fragment_surface` — per visible fragment: its world-space point (the
  perspective-correct barycentrics of the rasterizer applied to the world-space corners,
  ``Σ_k b_k·v_k`` — an affine map commutes with the barycentric sum, so this is the eye-space
  point mapped back to world space) and its triangle's world face normal, written into
  preallocated contiguous arrays, so the look-ups and the ray set-up read them without copies.
* :func:`hard_shadow_rays` — per receiver point: the float32 origin, unit direction and
  ``t_max`` of its shadow ray, as ``raytrace._hard_rays_numpy`` computes them (offset scaled
  with the point's distance from the scene centre), so that Embree gets one batch per light
  and no numpy temporaries are built around it.
* :func:`area_light_rays` — per point, the ray towards one jittered sample of an area light.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from compositing._threads import in_shares

__all__ = ["area_light_rays", "fragment_surface", "hard_shadow_rays"]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _hard_shadow_rays_share(
    share, points, normals, light, positional, centre, offset, ulps, o32, d32, t32
):  # pragma: no cover
    """Shadow rays of points for one light, written into float32 arrays (compiled).

    ``points``/``normals``: (n, 3) float64 world space; ``light``: unit direction towards a
    directional light, or the position of a point light (``positional``); ``centre``: the
    :class:`~blinn_phong.shadows.raytrace.RayScene` centre subtracted from the origins; ``offset``:
    smallest origin offset (world units), raised to ``ulps·‖p − centre‖∞``. Outputs: ``o32``
    (n, 3) recentred origins, ``d32`` (n, 3) unit directions, ``t32`` (n,) ``t_max``.
    Returns the number of rows with a non-finite point or normal (left unwritten).
    """
    bad = 0
    for i in share:
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        if not (math.isfinite(px + py + pz) and math.isfinite(nx + ny + nz)):
            bad += 1
            continue
        mag = max(abs(px - centre[0]), abs(py - centre[1]), abs(pz - centre[2]))
        eff = max(offset, ulps * mag)
        length = math.sqrt(nx * nx + ny * ny + nz * nz)
        if length > 0:
            nx, ny, nz = nx / length, ny / length, nz / length
        if positional:
            lx, ly, lz = light[0] - px, light[1] - py, light[2] - pz
        else:
            lx, ly, lz = light[0], light[1], light[2]
        side = -eff if nx * lx + ny * ly + nz * lz < 0 else eff
        ox, oy, oz = px + nx * side, py + ny * side, pz + nz * side
        if positional:
            dx, dy, dz = light[0] - ox, light[1] - oy, light[2] - oz
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            if dist > 0:
                dx, dy, dz = dx / dist, dy / dist, dz / dist
            t32[i] = max(dist - eff, 0.0)
        else:
            dx, dy, dz = lx, ly, lz
            t32[i] = 1e37
        o32[i, 0], o32[i, 1], o32[i, 2] = ox - centre[0], oy - centre[1], oz - centre[2]
        d32[i, 0], d32[i, 1], d32[i, 2] = dx, dy, dz
    return bad


def hard_shadow_rays(points: np.ndarray, *args: object) -> int:
    """The compiled :func:`_hard_shadow_rays_share` (same arguments, without ``share``) over every row, in
    shares on threads (:func:`compositing._threads.in_shares`); returns the sum of the shares'
    counts."""
    return int(sum(in_shares(_hard_shadow_rays_share, points.shape[0], points, *args)))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _area_light_rays_share(
    share, origins, s, t, corner, edge_u, edge_v, offset, d32, t32
):  # pragma: no cover - compiled
    """Shadow rays towards one jittered sample ``corner + s·edge_u + t·edge_v`` per point (compiled).

    ``origins``: (n, 3) float64 offset ray origins (world); ``s``, ``t``: (n,) sample
    coordinates in [0, 1]; ``offset``: (n,) gap left before the light. Writes ``d32`` (n, 3)
    unit directions and ``t32`` (n,) ``max(distance − offset, 0)``, as
    :func:`blinn_phong.shadows.raytrace.area_light_visibility` computes them with numpy.
    """
    for i in share:
        dx = (corner[0] + s[i] * edge_u[0] + t[i] * edge_v[0]) - origins[i, 0]
        dy = (corner[1] + s[i] * edge_u[1] + t[i] * edge_v[1]) - origins[i, 1]
        dz = (corner[2] + s[i] * edge_u[2] + t[i] * edge_v[2]) - origins[i, 2]
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        scale = 1.0 / dist if dist > 0 else 1.0
        d32[i, 0], d32[i, 1], d32[i, 2] = dx * scale, dy * scale, dz * scale
        t32[i] = max(dist - offset[i], 0.0)


def area_light_rays(origins: np.ndarray, *args: object) -> None:
    """The compiled :func:`_area_light_rays_share` (same arguments, without ``share``) over every row, in
    shares on threads (:func:`compositing._threads.in_shares`)."""
    in_shares(_area_light_rays_share, origins.shape[0], origins, *args)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _fragment_surface_share(
    share, triangle, bary, triangles, world_vertices, face_normals, out_points, out_normals
):  # pragma: no cover - compiled
    """World-space point and face normal of each fragment, in one compiled pass.

    ``triangle``: (n,) int64 triangle of each fragment; ``bary``: (n, 3) float64 its
    perspective-correct barycentrics; ``triangles``: (T, 3) int64 vertex indices;
    ``world_vertices``: (V, 3) float64 world positions; ``face_normals``: (T, 3) float64 unit
    world face normals. Writes ``out_points[i] = Σ_k bary[i, k]·world_vertices[triangles[t, k]]``
    (the formula of :func:`blinn_phong.geometry.raster.interpolate`, summed in the order k = 0, 1, 2) and
    ``out_normals[i] = face_normals[t]``, ``t = triangle[i]``.
    """
    for i in share:
        t = triangle[i]
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        w0, w1, w2 = bary[i, 0], bary[i, 1], bary[i, 2]
        for k in range(3):
            va, vb, vc = world_vertices[a, k], world_vertices[b, k], world_vertices[c, k]
            out_points[i, k] = (w0 * va + w1 * vb) + w2 * vc
            out_normals[i, k] = face_normals[t, k]


def fragment_surface(triangle: np.ndarray, *args: object) -> None:
    """The compiled :func:`_fragment_surface_share` (same arguments, without ``share``) over every row, in
    shares on threads (:func:`compositing._threads.in_shares`)."""
    in_shares(_fragment_surface_share, triangle.shape[0], triangle, *args)
