"""Planar projected ("fake") shadows (the ``planar`` method).

Planar projected shadows (Blinn, "Me and my (fake) shadow", IEEE CG&A 8(1) 1988): the
matrix ``M = (π·l) I − l πᵀ`` flattens geometry onto the plane ``π = (a, b, c, d)`` from
the homogeneous light ``l`` (w = 0 directional, w = 1 positional). Cheap, exact on that
one plane, and only there: no shadows on other receivers, and casters on the far side of
the plane or behind the light still cast.

Where every caster lies between the plane and the light, a point of the plane is in a
flattened caster exactly when its ray to the light crosses that caster: the frame's one BVH
answers it (:func:`planar_visibility`). Otherwise the flattened casters are tested directly
(:func:`planar_shadow_mask`).
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.shadows._inputs import checked_points, checked_triangles, homogeneous
from blinn_phong.shadows.method import ShadowFrame, ShadowMethod


def planar_shadow_matrix(
    plane: np.ndarray | tuple[float, ...], light: np.ndarray | tuple[float, ...]
) -> np.ndarray:
    """Blinn's projection onto a plane from a light: ``M = (π·l) I − l πᵀ``.

    Args:
        plane: ``(a, b, c, d)`` with the plane ``a·x + b·y + c·z + d = 0`` (world space).
        light: homogeneous light ``(x, y, z, w)``: w = 1 for a point light at (x, y, z),
            w = 0 for a directional light whose light lies towards (x, y, z).

    Returns:
        4×4 matrix acting on homogeneous column vectors; divide by w after applying it.
    """
    pl = np.asarray(plane, dtype=np.float64)
    lt = np.asarray(light, dtype=np.float64)
    if pl.shape != (4,) or lt.shape != (4,) or not (np.all(np.isfinite(pl)) and np.all(np.isfinite(lt))):
        raise ValueError(f"plane and light must each be 4 finite numbers, got {plane!r} and {light!r}")
    if np.linalg.norm(pl[:3]) == 0:
        raise ValueError(f"plane normal (a, b, c) must not be zero, got {plane!r}")
    dot = float(pl @ lt)
    if dot == 0:
        raise ValueError("the light lies in the plane (or is parallel to it): no projection exists")
    return dot * np.eye(4) - np.outer(lt, pl)


def planar_shadow_mask(
    occluder_triangles: np.ndarray,
    plane: np.ndarray | tuple[float, ...],
    light: np.ndarray | tuple[float, ...],
    points: np.ndarray,
) -> np.ndarray:
    """Fake shadows: which points of the plane fall inside the flattened occluders.

    Args:
        occluder_triangles: (n, 3, 3) world-space triangles of the shadow casters.
        plane: ``(a, b, c, d)``, see :func:`planar_shadow_matrix`.
        light: homogeneous light, see :func:`planar_shadow_matrix`.
        points: (m, 3) points on the plane.

    Returns:
        (m,) float64 visibility: 0 inside a projected occluder, 1 elsewhere.
    """
    tris = checked_triangles("occluder_triangles", occluder_triangles)
    p = checked_points("points", points)
    m = planar_shadow_matrix(plane, light)
    proj = homogeneous(tris.reshape(-1, 3)) @ m.T
    w = proj[:, 3].reshape(-1, 3)
    # a vertex level with a point light projects to infinity: such triangles are dropped
    finite = np.all(
        np.abs(w) > 1e-12 * np.abs(proj[:, :3]).reshape(-1, 9).max(axis=1, initial=1.0)[:, None], axis=1
    )
    proj = proj.reshape(-1, 3, 4)[finite]
    flat = proj[:, :, :3] / proj[:, :, 3:4]
    # point-in-triangle for every point at once: a short ray across the plane through the
    # flattened triangles, answered by Embree's BVH (edge-on, zero-area triangles never hit)
    from blinn_phong.shadows.raytrace import RayScene

    nrm = np.asarray(plane, dtype=np.float64)[:3]
    nrm = nrm / np.linalg.norm(nrm)
    if len(flat) == 0 or len(p) == 0:
        return np.ones(len(p))
    scale = max(float(np.abs(np.concatenate([flat.reshape(-1, 3), p])).max()), 1.0)
    h = 1e-3 * scale
    shadowed = RayScene(flat).occluded(p + h * nrm, np.broadcast_to(-nrm, p.shape), 2 * h)
    return 1.0 - shadowed.astype(np.float64)


#: The last :func:`_on_plane` answer: (weak reference to the points, plane bytes, result). The
#: lights of a frame test the same points against the same plane; the weak reference makes sure
#: the points are the very same array, still alive (an id alone could be reused).
_ON_PLANE: list[tuple[object, bytes, tuple[np.ndarray, np.ndarray, np.ndarray]]] = []


def _on_plane(p: np.ndarray, plane: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mask, points, normals): the points within ``1e-6·max|p|`` of the plane (the receivers of
    planar shadows), and the plane's normal for each, contiguous; reused for the frame's next light."""
    key = plane.tobytes()
    for ref, k, result in _ON_PLANE:
        if k == key and ref() is p:  # type: ignore[operator]
            return result
    scale = max(float(-p.min()), float(p.max()), 1.0) if len(p) else 1.0
    mask = np.abs(p @ plane[:3] + plane[3]) <= 1e-6 * scale
    q = p[mask]
    normals = np.empty_like(q)
    normals[:] = plane[:3]
    result = (mask, q, normals)
    try:
        _ON_PLANE[:] = [(weakref.ref(p), key, result)]
    except TypeError:  # an array that takes no weak reference: not kept
        _ON_PLANE.clear()
    return result


def _casters_between(height: np.ndarray, plane: np.ndarray, light: np.ndarray) -> bool:
    """True when every caster corner (signed ``height`` above ``plane``) lies on the light's side of
    the plane and, for a positional light, below the light's own height."""
    if len(height) == 0:
        return False
    side = float(plane @ light)  # > 0: the light is on the positive side (w = 0: its direction)
    if side == 0:
        return False
    h = height if side > 0 else -height
    if h.min() < 0:
        return False
    return bool(light[3] == 0 or h.max() < abs(side))


def planar_visibility(
    light: DirectionalLight | PointLight | SpotLight,
    tris: np.ndarray,
    p: np.ndarray,
    *,
    plane: np.ndarray | tuple[float, ...] | None = None,
    caster_triangles: np.ndarray | None = None,
    engine: str = "auto",
) -> np.ndarray:
    """(m,) visibility of the (m, 3) points ``p`` (checked by the caller) under planar shadows on
    ``plane`` ``(a, b, c, d)``: points off the plane are lit; on it, shadowed where a flattened
    caster covers them. ``caster_triangles`` default to every triangle of ``tris`` off the plane;
    ``engine`` is the ray tracer's where every caster lies between the plane and the light."""
    if plane is None:
        raise ValueError("planar shadows need the receiving plane (a, b, c, d)")
    pl = np.asarray(plane, dtype=np.float64)
    homogeneous_light = light.homogeneous()  # type: ignore[attr-defined]
    on_plane, q, q_normals = _on_plane(p, pl)
    vis = np.ones(len(p))
    between = False
    if caster_triangles is None:
        height = tris @ pl[:3] + pl[3]  # (n, 3) signed heights (times |(a, b, c)|) of the corners
        off_plane = np.abs(height).max(axis=1) > 1e-9 * max(np.abs(tris).max(), 1.0)
        caster_triangles = tris[off_plane]
        between = _casters_between(height[off_plane], pl, homogeneous_light)
    if not (len(caster_triangles) and on_plane.any()):
        return vis
    if between:
        # every caster lies between the plane and the light: a point of the plane is inside a
        # flattened caster exactly when its segment (ray) to the light crosses that caster, so
        # the frame's one BVH answers it (cached_ray_scene, shared with every other light)
        # instead of a new BVH of flattened triangles per light
        from blinn_phong.shadows.raytrace import (
            cached_ray_scene,
            directional_light_visibility,
            point_light_visibility,
        )

        scene = cached_ray_scene(tris)
        towards = homogeneous_light[:3]
        if homogeneous_light[3] == 0:
            vis[on_plane] = directional_light_visibility(scene, q, q_normals, towards, engine=engine)
        else:
            vis[on_plane] = point_light_visibility(scene, q, q_normals, towards, engine=engine)
        return vis
    vis[on_plane] = planar_shadow_mask(caster_triangles, pl, homogeneous_light, q)
    return vis


def planar_hard(frame: ShadowFrame, light: object, plane: object) -> np.ndarray | None:
    """Planar shadows at a frame's points where every caster lies between the plane and the
    light: the plane's points by :func:`blinn_phong.shadows.ray_traced.traced_hard` (the shadow
    rays this method casts against the frame's BVH, most answered by the ray culling), every
    other point lit. None where the casters are not all between (the method projects them
    instead). The plane's caster heights are shared between the frame's lights."""
    from blinn_phong.shadows.ray_traced import traced_hard

    tris, world = frame.tris, frame.world
    pl = np.asarray(plane, dtype=np.float64)
    homogeneous_light = light.homogeneous()  # type: ignore[attr-defined]
    key = ("plane", pl.tobytes())
    if key not in frame.cache:  # (else: the frame's other lights on the same plane)
        height = tris @ pl[:3] + pl[3]
        frame.cache[key] = (height, np.abs(height).max(axis=1) > 1e-9 * max(float(np.abs(tris).max()), 1.0))
    height, off_plane = frame.cache[key]  # type: ignore[misc]
    on_plane, q, q_normals = _on_plane(world, pl)
    vis = np.ones(len(world))
    if not (off_plane.any() and on_plane.any()):
        return vis
    if not _casters_between(height[off_plane], pl, homogeneous_light):
        return None
    vis[on_plane] = traced_hard(frame, light, q, q_normals, frame.mesh_of[on_plane])  # type: ignore[index]
    return vis


def _at_frame(frame: ShadowFrame, light: object, params: dict) -> np.ndarray:
    if frame.culled and set(params) == {"plane"}:
        vis = planar_hard(frame, light, params["plane"])
        if vis is not None:
            return vis
    return planar_visibility(light, frame.tris, frame.world, **params)  # type: ignore[arg-type]


def _choice_params(options: Any, planned: Any) -> tuple[dict, str]:
    plane = options.plane if options.plane is not None else planned.params.get("plane")
    if plane is None:
        raise ValueError(
            "shadows: 'planar' needs the receiving plane; pass ShadowOptions(method='planar', "
            f"plane=(a, b, c, d)) (the planner chose {planned.method!r}, which gives none)"
        )
    return {"plane": plane}, ""


METHOD = ShadowMethod(
    name="planar",
    title="planar projected shadows",
    summary="casters flattened onto one receiving plane (Blinn 1988): exact on that plane only",
    exact=False,
    coloured=False,
    uses_rays=True,
    without_embree="shadow_volume",
    cost_model=None,
    parameters=("plane", "caster_triangles", "engine"),
    visibility=lambda light, tris, p, normals=None, **params: planar_visibility(light, tris, p, **params),
    frame_visibility=_at_frame,
    choice_params=_choice_params,
)
