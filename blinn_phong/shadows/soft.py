"""Soft shadows of a point or spot light given an area (the ``soft`` method): the fraction of a
square area light each point sees, by stratified shadow rays cast with Embree
(:func:`blinn_phong.shadows.raytrace.area_light_visibility`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from blinn_phong.model.lights import PointLight, SpotLight
from blinn_phong.shadows.method import ShadowFrame, ShadowMethod


def soft_visibility(
    light: PointLight | SpotLight,
    tris: np.ndarray,
    p: np.ndarray,
    normals: np.ndarray,
    *,
    radius: float,
    samples_per_axis: int,
    offset: float,
    aim: np.ndarray | None = None,
    ray_scene: object = None,
) -> np.ndarray:
    """(m,) fraction in [0, 1] of a square light of side ``2·radius`` (world units) at the light's
    position that each of the (m, 3) points ``p`` sees past the (n, 3, 3) casters ``tris``.

    The square faces along a spot light's axis, else towards ``aim`` (by default the centre of the
    casters' bounding box, never the camera's view); ``samples_per_axis``² stratified rays per
    point, each starting ``offset`` along the point's normal. ``ray_scene``: the casters' BVH when
    the caller has it (:func:`blinn_phong.shadows.raytrace.cached_ray_scene` of ``tris``)."""
    from blinn_phong.shadows.raytrace import (  # Embree: imported only when used
        area_light_visibility,
        cached_ray_scene,
    )

    if ray_scene is None:
        ray_scene = cached_ray_scene(tris)
    centre = np.asarray(light.position, dtype=np.float64)
    if aim is None:
        corners = ray_scene.triangles.reshape(-1, 3)  # type: ignore[attr-defined]
        aim = (corners.min(axis=0) + corners.max(axis=0)) / 2
    axis = aim - centre
    if light.axis is not None:  # a spot light faces along its axis
        axis = np.array(light.axis, dtype=np.float64)
    if float(np.linalg.norm(axis)) < 1e-12:
        axis = np.array([0.0, 0.0, -1.0])  # the light at the scene's centre: any orientation
    axis /= float(np.linalg.norm(axis))
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    return area_light_visibility(
        ray_scene,
        p,
        normals,
        centre - radius * (u + v),
        2 * radius * u,
        2 * radius * v,
        samples_per_axis=int(samples_per_axis),
        offset=float(offset),
    )


def _at_frame(frame: ShadowFrame, light: object, params: dict) -> np.ndarray:
    return soft_visibility(
        light,  # type: ignore[arg-type]
        frame.tris,
        frame.world,
        frame.normal,
        radius=float(params["radius"]),
        samples_per_axis=int(params["samples_per_axis"]),
        offset=float(params["offset"]),
        aim=frame.aim,
        ray_scene=frame.ray_scene(),  # the frame's one BVH, shared with hard shadows
    )


def _choice_params(options: Any, planned: Any) -> tuple[dict, str]:
    m = max(1, round(math.sqrt(options.samples)))
    if m * m == options.samples:
        return {"samples_per_axis": m, "radius": options.radius, "offset": options.offset}, ""
    note = f"{options.samples} samples asked, {m}×{m} = {m * m} cast (strata are square)"
    return {"samples_per_axis": m, "radius": options.radius, "offset": options.offset}, note


def _stand_in(light: object, options: Any) -> tuple[str, str] | None:
    if light.positional and options.radius > 0.0:  # type: ignore[attr-defined]
        return None
    why = "radius 0" if light.positional else f"a {type(light).__name__} (at infinity)"  # type: ignore[attr-defined]
    return "ray_traced", f"soft shadows asked for, but {why} has no area: hard ray-traced shadows"


METHOD = ShadowMethod(
    name="soft",
    title="soft shadows",
    summary="the fraction of a square area light each point sees, by stratified rays cast with Embree",
    exact=False,
    coloured=False,
    uses_rays=True,
    without_embree="shadow_map",
    cost_model=None,
    parameters=("radius", "samples_per_axis", "offset"),
    visibility=soft_visibility,
    frame_visibility=_at_frame,
    choice_params=_choice_params,
    stand_in=_stand_in,
)
