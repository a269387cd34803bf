"""Ray-traced hard shadows (the ``ray_traced`` method): one shadow ray per point towards the light,
cast with Embree against the casters (:mod:`blinn_phong.shadows.raytrace`).

Exact, and the one method whose shadows transparent casters colour: with per-triangle RGB
transmittances the light that arrives is the product of the transmittances the ray crosses
(:func:`blinn_phong.shadows.raytrace.transmitted_light`). In a frame on the compiled engine the
rays whose answer the geometry already proves (:mod:`blinn_phong.shadows.ray_culling`) are not
cast (:func:`traced_hard`).
"""

from __future__ import annotations

import numpy as np

from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.shadows._inputs import trusted_arrays
from blinn_phong.shadows.method import ShadowFrame, ShadowMethod


def ray_target(light: object) -> tuple[np.ndarray, bool]:
    """``(vector, positional)`` of a light's shadow rays, as the ray tracer takes them: the unit
    direction towards a directional light, else the light's position."""
    h = light.homogeneous()  # type: ignore[attr-defined]
    if h[3] == 0:
        return h[:3] / np.linalg.norm(h[:3]), False
    return h[:3], True


def hard_visibility(
    light: DirectionalLight | PointLight | SpotLight,
    tris: np.ndarray,
    p: np.ndarray,
    normals: np.ndarray,
    *,
    engine: str = "auto",
    transmittance: np.ndarray | None = None,
) -> np.ndarray:
    """(m,) visibility (1 lit, 0 shadowed) of the (m, 3) points ``p`` with their normals by one
    shadow ray each towards ``light``, against the (n, 3, 3) casters ``tris`` (both checked by
    the caller); ``engine`` sets up the rays (numpy reference or compiled, the same rays).

    With ``transmittance`` ((n, 3) RGB per caster, 0 opaque) the result is (m, 3): the fraction
    of the light each channel keeps along the ray (coloured shadows)."""
    from blinn_phong.shadows.raytrace import (  # Embree: imported only when used
        cached_ray_scene,
        directional_light_visibility,
        point_light_visibility,
        transmitted_light,
    )

    scene = cached_ray_scene(tris)  # one BVH for every light of a frame
    h = light.homogeneous()  # (−direction, 0) or (position, 1)
    if transmittance is not None:
        return transmitted_light(scene, p, normals, h[:3], transmittance, positional=light.positional)
    if light.positional:
        return point_light_visibility(scene, p, normals, h[:3], engine=engine)
    return directional_light_visibility(scene, p, normals, h[:3], engine=engine)


def _ray_answers(
    light: object,
    world: np.ndarray,
    normal: np.ndarray,
    mesh_of: np.ndarray,
    centre: np.ndarray,
    tables: tuple[np.ndarray, ...],
) -> np.ndarray:
    """:func:`blinn_phong.shadows.ray_culling.rays_to_trace` for the hard shadow rays of ``light``
    as the ray tracer builds them (default offset, offset scale, BVH ``centre``)."""
    from blinn_phong.shadows import raytrace  # Embree: imported only when used
    from blinn_phong.shadows.ray_culling import rays_to_trace

    vec, positional = ray_target(light)
    offset, scale = raytrace.HARD_SHADOW_OFFSET, raytrace.offset_scale()
    return rays_to_trace(world, normal, mesh_of, vec, positional, centre, offset, scale, tables)


def traced_hard(
    frame: ShadowFrame, light: object, world: np.ndarray, normal: np.ndarray, mesh_of: np.ndarray
) -> np.ndarray:
    """Ray-traced hard visibility of one light at frame points, tracing only the rays the geometry
    cannot answer.

    :mod:`blinn_phong.shadows.ray_culling` proves most rays lit or shadowed (the answers Embree
    gives); the rest go to :func:`hard_visibility` in one batch. The frame's caster tables are
    built once and shared between its lights (``frame.cache``).
    """
    from blinn_phong.shadows.ray_culling import LIT, TRACE, caster_tables

    bvh = frame.ray_scene()
    if "tables" not in frame.cache:
        frame.cache["tables"] = caster_tables(frame.scene, bvh.centre)  # type: ignore[attr-defined]
    answer = _ray_answers(light, world, normal, mesh_of, bvh.centre, frame.cache["tables"])  # type: ignore[arg-type, attr-defined]
    out = (answer == LIT).astype(np.float64)
    index = np.flatnonzero(answer == TRACE)
    if len(index):
        p, n = world[index], normal[index]
        with trusted_arrays(p, n):
            out[index] = hard_visibility(light, frame.tris, p, n, engine="numba")  # type: ignore[arg-type]
    return out


def _at_frame(frame: ShadowFrame, light: object, params: dict) -> np.ndarray:
    if frame.transmittance is not None:
        return hard_visibility(
            light, frame.tris, frame.world, frame.normal, transmittance=frame.transmittance  # type: ignore[arg-type]
        )
    if frame.culled and not params:
        return traced_hard(frame, light, frame.world, frame.normal, frame.mesh_of)  # type: ignore[arg-type]
    engine = str(params.get("engine", frame.engine))
    return hard_visibility(light, frame.tris, frame.world, frame.normal, engine=engine)  # type: ignore[arg-type]


METHOD = ShadowMethod(
    name="ray_traced",
    title="ray-traced shadows",
    summary="one shadow ray per point, cast with Embree: exact, coloured by transparent casters",
    exact=True,
    coloured=True,
    uses_rays=True,
    without_embree="shadow_volume",
    cost_model="ray_traced",
    parameters=("engine",),
    visibility=hard_visibility,
    frame_visibility=_at_frame,
)
